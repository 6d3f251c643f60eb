"""The rosbags type stores, imported lazily (:func:`semattnet._utils.extras.require`: one line with the install hint).

``rosbags`` (extra ``ros``) reads and writes ROS 1 bags and ROS 2 bags (sqlite3, MCAP) without a ROS
installation; ``rerun-sdk`` (extra ``rerun``) writes Rerun recordings. Nothing here imports them at
module import time, so ``import semattnet`` works without either.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache
from typing import Protocol

from semattnet._utils.extras import require

__all__ = ["NODE_MSGS", "Typestore", "add_missing_types", "rosbags_typestore", "writes_mcap"]

#: The ROS 1 ``tf2_msgs/TFMessage`` definition (rosbags' Noetic store lacks it).
_TF_MESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms"
#: Humble's definitions of the types the live node publishes beside its frames (``/diagnostics``,
#: ``ros_discovery_info``), registered where a rosbags store lacks them (rmw_dds_common: ROS 2 only).
NODE_MSGS = {
    "diagnostic_msgs/msg/KeyValue": "string key\nstring value",
    "diagnostic_msgs/msg/DiagnosticStatus": "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\n"
    "string name\nstring message\nstring hardware_id\nKeyValue[] values",
    "diagnostic_msgs/msg/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status",
    "rmw_dds_common/msg/Gid": "char[24] data",
    "rmw_dds_common/msg/NodeEntitiesInfo": "string<=256 node_namespace\nstring<=256 node_name\nGid[] reader_gid_seq\n"
    "Gid[] writer_gid_seq",
    "rmw_dds_common/msg/ParticipantEntitiesInfo": "Gid gid\nNodeEntitiesInfo[] node_entities_info_seq",
}


class Typestore(Protocol):
    """What semattnet uses of a rosbags type store: its message classes by type name and the serialisers."""

    @property
    def types(self) -> Mapping[str, type]: ...

    def serialize_ros1(self, message: object, typename: str) -> memoryview: ...

    def serialize_cdr(self, message: object, typename: str) -> memoryview: ...

    def deserialize_cdr(self, rawdata: bytes, typename: str) -> object: ...

    def register(self, typs: Mapping[str, object]) -> None: ...


@lru_cache(maxsize=2)
def rosbags_typestore(ros1: bool) -> Typestore:
    """The rosbags type store used to write (and to read bags without embedded definitions): ROS 1 Noetic
    (plus ``tf2_msgs/TFMessage``) or ROS 2 Humble."""
    typesys = require("rosbags.typesys", "reading or writing ROS bags")
    store: Typestore = typesys.get_typestore(typesys.Stores.ROS1_NOETIC if ros1 else typesys.Stores.ROS2_HUMBLE)
    add_missing_types(store, ros1)
    if not ros1:
        return store
    if "tf2_msgs/msg/TFMessage" not in store.types:
        store.register(typesys.get_types_from_msg(_TF_MESSAGE_MSG, "tf2_msgs/msg/TFMessage"))
    return store


def add_missing_types(store: Typestore, ros1: bool = False) -> None:
    """Register the :data:`NODE_MSGS` types ``store`` lacks (an older rosbags), from their .msg text."""
    typesys = require("rosbags.typesys", "reading or writing ROS bags")
    wanted = {k: v for k, v in NODE_MSGS.items() if not (ros1 and k.startswith("rmw_dds_common/"))}
    missing: dict[str, object] = {}
    for name, text in wanted.items():
        if name not in store.types:
            missing.update(typesys.get_types_from_msg(text, name))
    if missing:
        store.register(missing)


def writes_mcap() -> bool:
    """Whether the installed rosbags writes ROS 2 bags in MCAP storage (rosbags >= 0.10)."""
    enums = require("rosbags.rosbag2", "writing ROS 2 bags")
    return hasattr(getattr(enums, "StoragePlugin", None), "MCAP")
