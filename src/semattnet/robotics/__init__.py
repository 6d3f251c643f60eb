"""The project's robot I/O: ROS bags, Rerun and the live server.

- :class:`LiveSink` (:mod:`.live`): each completed frame served over the Foxglove WebSocket protocol
  (``semattnet predict --live``; ``foxglove-sdk``, extra ``live``).
- ROS bags and Rerun recordings: :mod:`semattnet.data.bags`.

Importing this package imports no optional dependency (and not torch): :class:`LiveSink` is loaded on
first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .live import LiveSink

__all__ = ["LiveSink"]


def __getattr__(name: str) -> Any:
    """Load :class:`LiveSink` on first access (it imports the inference sinks)."""
    if name == "LiveSink":
        from .live import LiveSink

        return LiveSink
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
