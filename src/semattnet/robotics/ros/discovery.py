"""The ROS 2 graph's view of the node: ``ros_discovery_info``, as ``rmw_cyclonedds`` publishes it.

A DDS participant is mapped to ROS 2 nodes by the ``rmw_dds_common/msg/ParticipantEntitiesInfo`` samples it
writes on the DDS topic ``ros_discovery_info`` (no ``rt/`` prefix; reliable, transient local, keep last 1):
the participant's GID and, per node, its namespace, name and the GIDs of its readers and writers. ``ros2 node
list`` and ``ros2 topic info -v`` read them. A GID (``rmw_gid_t``, Humble's ``Gid.msg``: ``char[24] data``) of
a Cyclone DDS entity is its 16-byte GUID (``dds_guid_t.v``: prefix, then entity id) followed by 8 zero bytes.
The participant carries ``enclave=ENCLAVE;`` in its USER_DATA, as ``rmw_cyclonedds`` sets it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import DataError

from .transport import QoS

if TYPE_CHECKING:
    from semattnet.robotics.bags.deps import Typestore

__all__ = [
    "DISCOVERY_QOS",
    "DISCOVERY_TOPIC",
    "DISCOVERY_TYPE",
    "GID_SIZE",
    "NodeEntities",
    "enclave_user_data",
    "gid_bytes",
]

#: The DDS topic (not a ROS topic: no ``rt/`` prefix).
DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
#: rmw_cyclonedds' QoS for it: reliable, transient local, keep last 1.
DISCOVERY_QOS = QoS(reliable=True, depth=1, durable=True)
#: Bytes of a GID in Humble (``RMW_GID_STORAGE_SIZE``).
GID_SIZE = 24


def gid_bytes(guid: bytes) -> bytes:
    """The GID of a DDS entity whose GUID is ``guid`` (16 bytes): the GUID, zero-padded to :data:`GID_SIZE`."""
    if len(guid) != 16:
        raise DataError(f"a DDS GUID is 16 bytes, not {len(guid)}")
    return guid + bytes(GID_SIZE - len(guid))


def enclave_user_data(enclave: str = "/") -> bytes:
    """The participant's USER_DATA: ``enclave=/;`` for the root enclave."""
    return f"enclave={enclave};".encode()


@dataclass
class NodeEntities:
    """One node's part of the graph: its namespace (``/`` for the root), name, and its readers' and writers'
    GUIDs; :meth:`message` is the participant's ``ParticipantEntitiesInfo``."""

    namespace: str
    name: str
    readers: list[bytes] = field(default_factory=list)
    writers: list[bytes] = field(default_factory=list)

    def message(self, ts: Typestore, participant: bytes, present: bool = True) -> object:
        """The ``ParticipantEntitiesInfo`` of the participant whose GUID is ``participant`` (``present``: False,
        the node left: no node)."""
        gid_cls = ts.types["rmw_dds_common/msg/Gid"]
        node_cls = ts.types["rmw_dds_common/msg/NodeEntitiesInfo"]

        def gid(guid: bytes) -> object:
            return gid_cls(data=np.frombuffer(gid_bytes(guid), np.uint8).copy())

        node = node_cls(
            node_namespace=self.namespace or "/",
            node_name=self.name,
            reader_gid_seq=[gid(g) for g in self.readers],
            writer_gid_seq=[gid(g) for g in self.writers],
        )
        return ts.types[DISCOVERY_TYPE](gid=gid(participant), node_entities_info_seq=[node] if present else [])
