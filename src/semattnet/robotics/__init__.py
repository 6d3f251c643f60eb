"""The project's robot I/O, in one room: ROS bags in and out, Rerun, and the live server.

- :class:`BagSource` (:mod:`.bag_source`): a ROS 1 / ROS 2 (sqlite3, MCAP) bag as frames, images paired with
  scans by stamp, each scan projected as :class:`~semattnet.data.sources.RawDriveSource` does; a bad message
  fails its frame only.
- :mod:`.bags`: reading (pairing, decoding, ``/tf_static``) and writing bags (``rosbags``, extra ``ros``).
- :mod:`.sinks`: :class:`BagSink` (``--bag-out``) and :class:`RerunSink` (``--rerun``, ``--rerun-spawn``,
  ``--rerun-serve``; :class:`~.rerun.RerunLogger`, extra ``rerun``).
- :class:`LiveSink` (:mod:`.live`): each completed frame served over the Foxglove WebSocket protocol
  (``semattnet predict --live``; ``foxglove-sdk``, extra ``live``).

Importing this package enrols its frame source and its sinks in the frame loop's registries
(:data:`~semattnet.data.sources.registry.SOURCES`, :data:`~semattnet.inference.sinks.SINKS`); it imports no optional
dependency: ``rosbags``, ``rerun-sdk`` and ``foxglove-sdk`` are loaded on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: The modules that enrol the bag source and the robot sinks, imported with the package (in the order ``predict
#: --help`` lists them).
ENROLLING = (".bag_source", ".sinks", ".live")
for _home in ENROLLING:
    importlib.import_module(_home, __name__)

if TYPE_CHECKING:
    from .bag_source import BagSource
    from .live import LiveSink
    from .rerun import RerunLogger
    from .sinks import BagSink, RerunSink

__all__ = ["BagSink", "BagSource", "LiveSink", "RerunLogger", "RerunSink"]

_HOMES = {
    "BagSink": ".sinks",
    "BagSource": ".bag_source",
    "LiveSink": ".live",
    "RerunLogger": ".rerun",
    "RerunSink": ".sinks",
}


def __getattr__(name: str) -> object:
    """Load a class on first access."""
    if name in _HOMES:
        return getattr(importlib.import_module(_HOMES[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
