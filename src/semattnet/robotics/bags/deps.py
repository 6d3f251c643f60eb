"""The optional packages the bag and Rerun layers need, imported lazily with an install hint.

``rosbags`` (extra ``ros``) reads and writes ROS 1 bags and ROS 2 bags (sqlite3, MCAP) without a ROS
installation; ``rerun-sdk`` (extra ``rerun``) writes Rerun recordings. Nothing here imports them at
module import time, so ``import semattnet`` works without either.
"""

from __future__ import annotations

import importlib
from functools import lru_cache
from types import ModuleType
from typing import Any

from semattnet._errors import SemAttNetError

__all__ = ["MissingExtraError", "import_extra", "rosbags_typestore", "writes_mcap"]

#: Which extra installs each optional top-level module.
EXTRAS = {"rosbags": "ros", "rerun": "rerun"}

#: The ROS 1 ``tf2_msgs/TFMessage`` definition (rosbags' Noetic store lacks it).
_TF_MESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms"


class MissingExtraError(SemAttNetError):
    """An optional package (``rosbags``, ``rerun-sdk``) is not installed."""


def import_extra(module: str, what: str = "this") -> ModuleType:
    """``importlib.import_module(module)``, or a one-line :class:`MissingExtraError` with the install hint."""
    top = module.split(".")[0]
    try:
        return importlib.import_module(module)
    except ImportError:
        extra = EXTRAS.get(top, top)
        raise MissingExtraError(
            f"{what} needs the optional package {top!r}: pip install 'semattnet[{extra}]'"
        ) from None


@lru_cache(maxsize=2)
def rosbags_typestore(ros1: bool) -> Any:
    """The rosbags type store used to write (and to read bags without embedded definitions): ROS 1 Noetic
    (plus ``tf2_msgs/TFMessage``) or ROS 2 Humble."""
    typesys = import_extra("rosbags.typesys", "reading or writing ROS bags")
    if not ros1:
        return typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
    store = typesys.get_typestore(typesys.Stores.ROS1_NOETIC)
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(typesys.get_types_from_msg(_TF_MESSAGE_MSG, "tf2_msgs/msg/TFMessage"))
    return store


def writes_mcap() -> bool:
    """Whether the installed rosbags writes ROS 2 bags in MCAP storage (rosbags >= 0.10)."""
    enums = import_extra("rosbags.rosbag2", "writing ROS 2 bags")
    return hasattr(getattr(enums, "StoragePlugin", None), "MCAP")
