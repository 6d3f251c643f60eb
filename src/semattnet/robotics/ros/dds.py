"""ROS 2 over DDS without rclpy: a :class:`~.transport.Transport` on ``cyclonedds`` (extra ``ros2``).

ROS 2 *is* DDS on the wire: topic ``/ns/name`` is the DDS topic ``rt/ns/name`` and type
``sensor_msgs/msg/Image`` is ``sensor_msgs::msg::dds_::Image_`` (nested types alike), final extensibility,
no keys, XCDR1 data. The DDS types are built from the ``rosbags`` definitions with ROS ``uint8`` declared
as octets (Cyclone 0.10, what Humble and Jazzy ship, cannot parse the XTypes object of ``uint8``; the bytes
are the same). The samples carry ``rosbags``' CDR bytes as they are (``serialize_cdr`` /
``deserialize_cdr``): cyclonedds' own Python serialiser is ~30x slower on images.

The node is in the ROS 2 graph as ``rmw_cyclonedds`` puts it there (:mod:`.discovery`): the participant's
USER_DATA ``enclave=/;`` and, on ``ros_discovery_info``, its node's namespace, name and endpoint GIDs,
published again whenever an endpoint is added and emptied on close.

``loopback=True`` keeps DDS on ``lo`` by unicast (no multicast, peer 127.0.0.1): what the tests use, and
what two processes on one machine need where multicast is off. On a robot's LAN Cyclone's defaults are kept
(:func:`network_config`) and ``domain_id`` is ``ROS_DOMAIN_ID``. Either way the sockets ask for 4 MB buffers,
unless ``CYCLONEDDS_URI`` is set (the user's configuration then rules).
"""

from __future__ import annotations

import logging
import os
import threading
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from semattnet._errors import InputError
from semattnet._utils.extras import require
from semattnet.robotics.bags.deps import Typestore, rosbags_typestore

from .discovery import DISCOVERY_QOS, DISCOVERY_TOPIC, DISCOVERY_TYPE, NodeEntities, enclave_user_data
from .transport import QoS

__all__ = ["DdsTransport", "dds_topic", "dds_type_name", "loopback_config", "network_config"]

log = logging.getLogger(__name__)

#: Largest DDS domain id (the RTPS port mapping leaves room for 0-232).
MAX_DOMAIN_ID = 232
#: Socket buffers asked for (large images: the 212 KB default loses frames).
SOCKET_BUFFER = "4MB"


def dds_topic(topic: str) -> str:
    """``/ns/name`` -> ``rt/ns/name`` (the ROS 2 topic prefix)."""
    if not topic.startswith("/"):
        raise InputError(f"topic {topic!r}: expected an absolute ROS name (/ns/name)")
    return "rt" + topic


def dds_type_name(msgtype: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_``."""
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def _buffers() -> str:
    return "".join(f'<Socket{k}BufferSize min="default" max="{SOCKET_BUFFER}"/>' for k in ("Receive", "Send"))


def network_config(domain_id: int) -> str:
    """The Cyclone XML for a robot's network: Cyclone's defaults (every interface, multicast discovery) with the
    socket buffers large images need (:data:`SOCKET_BUFFER`; the kernel's 212 KB default loses frames)."""
    return f'<CycloneDDS><Domain id="{domain_id}"><Internal>{_buffers()}</Internal></Domain></CycloneDDS>'


def loopback_config(domain_id: int) -> str:
    """The Cyclone XML for unicast DDS on ``lo`` only (module doc), with the same socket buffers."""
    general = '<Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast>'
    discovery = (
        "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>"
        '<Peers><Peer address="127.0.0.1"/></Peers>'
    )
    buffers = _buffers()
    return (
        f'<CycloneDDS><Domain id="{domain_id}"><General>{general}</General><Discovery>{discovery}</Discovery>'
        f"<Internal>{buffers}</Internal></Domain></CycloneDDS>"
    )


class _RawSample(Protocol):
    """A sample of a raw struct (:func:`_raw_cdr`): its CDR bytes."""

    cdr: bytes


class _Entity(Protocol):
    """A Cyclone DDS entity (participant, reader, writer, domain): deleted explicitly; its GUID."""

    @property
    def guid(self) -> uuid.UUID: ...

    def __del__(self) -> None: ...


class _DataWriter(_Entity, Protocol):
    def write(self, sample: _RawSample) -> None: ...


class _DataReader(_Entity, Protocol):
    def take(self, N: int) -> list[_RawSample]: ...  # (a writer that went away: a sample without ``cdr``)


def _serialize(
    self: _RawSample, buffer: object = None, endianness: object = None, use_version_2: object = None
) -> bytes:
    return bytes(self.cdr)


def _deserialize(
    cls: type[_RawSample], data: bytes, has_header: bool = True, use_version_2: object = None
) -> _RawSample:
    sample = cls.__new__(cls)
    sample.cdr = bytes(data)
    return sample


def _raw_cdr(cls: Any) -> Any:
    """``cls`` whose samples are their CDR bytes (``sample.cdr``, encapsulation header included): cyclonedds
    calls these instead of its Python (de)serialiser (the type object stays the struct's)."""
    cls.serialize = _serialize
    cls.deserialize = classmethod(_deserialize)
    cls.deserialize_key = classmethod(lambda c, data, has_header=True, use_version_2=None: _deserialize(c, b""))
    return cls


class _Types:
    """DDS struct classes of ROS message types, built once per type from a rosbags type store."""

    def __init__(self, ts: Any) -> None:
        self.ts = ts
        self._built: dict[tuple[str, bool], type[_RawSample]] = {}
        idl = require("cyclonedds.idl", "semattnet ros2 (DDS)")
        self.idl, self.t = idl, require("cyclonedds.idl.types", "semattnet ros2 (DDS)")
        t = self.t
        self.base = {
            "bool": bool,
            "byte": t.byte,
            "char": t.byte,
            "int8": t.byte,
            "uint8": t.byte,
            "int16": t.int16,
            "uint16": t.uint16,
            "int32": t.int32,
            "uint32": t.uint32,
            "int64": t.int64,
            "uint64": t.uint64,
            "float32": t.float32,
            "float64": t.float64,
            "string": str,
        }

    def _field(self, node: Any) -> Any:
        kind, spec = node
        kind = int(kind)
        if kind == 1:  # base
            name, bound = spec
            return self.t.bounded_str[bound] if name == "string" and bound else self.base[name]
        if kind == 2:  # another message
            return self.struct(spec)
        inner, size = spec
        item = self._field(inner)
        if kind == 3:  # fixed array
            return self.t.array[item, size]
        return self.t.sequence[item, size] if size else self.t.sequence[item]

    def struct(self, msgtype: str, raw: bool = False) -> type[_RawSample]:
        """The struct class of ``msgtype`` (``raw``: the top-level one, whose samples are their CDR bytes)."""
        key = (msgtype, raw)
        if key not in self._built:
            if msgtype not in self.ts.fielddefs:
                raise InputError(f"message type {msgtype!r}: not a ROS 2 type rosbags knows")
            fields = {name: self._field(node) for name, node in self.ts.fielddefs[msgtype][1]}
            name = msgtype.replace("/", "_") + ("_raw" if raw else "")
            cls = self.idl.annotations.final(self.idl.make_idl_struct(name, dds_type_name(msgtype), fields))
            self._built[key] = _raw_cdr(cls) if raw else cls
        return self._built[key]


def _qos(qos: QoS) -> object:
    core = require("cyclonedds.core", "semattnet ros2 (DDS)")
    P = core.Policy
    reliability = P.Reliability.Reliable(max_blocking_time=100_000_000) if qos.reliable else P.Reliability.BestEffort
    durability = P.Durability.TransientLocal if qos.durable else P.Durability.Volatile
    return core.Qos(
        reliability, durability, P.History.KeepLast(qos.depth), P.DataRepresentation(use_cdrv0_representation=True)
    )


class _Writer:
    """One advertised topic: serialises with rosbags' CDR and writes the bytes."""

    def __init__(self, writer: _DataWriter, cls: type[_RawSample], ts: Typestore, msgtype: str) -> None:
        self._writer, self._cls, self._ts, self._msgtype = writer, cls, ts, msgtype

    @property
    def guid(self) -> uuid.UUID:
        """The DDS writer's GUID."""
        return self._writer.guid

    def publish(self, message: object) -> None:
        sample = self._cls.__new__(self._cls)
        sample.cdr = bytes(self._ts.serialize_cdr(message, self._msgtype))
        self._writer.write(sample)


class DdsTransport:
    """A ROS 2 participant on DDS domain ``domain_id`` (module doc).

    Raises:
        InputError: a domain id outside 0-232.
        MissingDependencyError: no ``cyclonedds`` (``pip install 'semattnet[ros2]'``).
    """

    name = "dds"

    def __init__(
        self,
        domain_id: int = 0,
        loopback: bool = False,
        *,
        namespace: str = "",
        node_name: str = "semattnet",
        enclave: str = "/",
    ) -> None:
        if not 0 <= int(domain_id) <= MAX_DOMAIN_ID:
            raise InputError(f"--domain-id: expected 0-{MAX_DOMAIN_ID}, got {domain_id}")
        domain = require("cyclonedds.domain", "semattnet ros2 (DDS)")
        core = require("cyclonedds.core", "semattnet ros2 (DDS)")
        self.domain_id, self.typestore = int(domain_id), rosbags_typestore(False)
        self._types = _Types(self.typestore)
        # the domain configured by this process (socket buffers; loopback), unless the user's CYCLONEDDS_URI rules
        self._configured = bool(loopback) or not os.environ.get("CYCLONEDDS_URI", "").strip()
        if self._configured:
            config = loopback_config if loopback else network_config
            _open_domain(self.domain_id, config(self.domain_id))
        qos = core.Qos(core.Policy.Userdata(data=enclave_user_data(enclave)))
        self._participant = domain.DomainParticipant(self.domain_id, qos=qos)
        self._entities: list[_Entity] = []
        self._lock = threading.Lock()
        self._closed = False
        self.graph = NodeEntities(namespace, node_name)
        self._graph_writer = self._writer(DISCOVERY_TOPIC, DISCOVERY_TYPE, DISCOVERY_QOS)
        self._announce()

    @property
    def guid(self) -> bytes:
        """The participant's DDS GUID (16 bytes)."""
        return bytes(self._participant.guid.bytes)

    def _writer(self, dds_name: str, msgtype: str, qos: QoS) -> _Writer:
        pub, tp = require("cyclonedds.pub", "semattnet ros2"), require("cyclonedds.topic", "semattnet ros2")
        cls = self._types.struct(msgtype, raw=True)
        writer = pub.DataWriter(self._participant, tp.Topic(self._participant, dds_name, cls), qos=_qos(qos))
        self._entities.append(writer)
        return _Writer(writer, cls, self.typestore, msgtype)

    def _announce(self, present: bool = True) -> None:
        """Publish the node's ``ros_discovery_info`` (``present``: False, the node left)."""
        self._graph_writer.publish(self.graph.message(self.typestore, self.guid, present))

    def advertise(self, topic: str, msgtype: str, qos: QoS) -> _Writer:
        """A writer of ``topic`` (see :class:`~.transport.Transport`), announced in ``ros_discovery_info``."""
        writer = self._writer(dds_topic(topic), msgtype, qos)
        self.graph.writers.append(bytes(writer.guid.bytes))
        self._announce()
        return writer

    def subscribe(self, topic: str, msgtype: str, qos: QoS, callback: Callable[[object], None]) -> None:
        """Deliver each message of ``topic`` to ``callback`` from Cyclone's listener thread; a message that does
        not deserialise is one logged line naming the topic."""
        core, sub = require("cyclonedds.core", "semattnet ros2"), require("cyclonedds.sub", "semattnet ros2")
        tp = require("cyclonedds.topic", "semattnet ros2")
        cls = self._types.struct(msgtype, raw=True)

        made: list[_DataReader] = []

        def on_data(reader: _DataReader | None) -> None:
            reader = reader if reader is not None else (made[0] if made else None)
            if reader is None:  # called while the reader is made (a durable topic's history): taken below
                return
            for sample in reader.take(N=64):
                if not getattr(sample, "cdr", b""):  # a writer went away: a sample without data
                    continue
                self._deliver(topic, msgtype, sample.cdr, callback)

        listener = core.Listener(on_data_available=on_data)
        reader = sub.DataReader(
            self._participant, tp.Topic(self._participant, dds_topic(topic), cls), qos=_qos(qos), listener=listener
        )
        made.append(reader)
        self._entities.append(reader)
        self.graph.readers.append(bytes(reader.guid.bytes))
        self._announce()
        on_data(reader)  # what arrived before the listener could name its reader

    def _deliver(self, topic: str, msgtype: str, cdr: bytes, callback: Callable[[object], None]) -> None:
        if self._closed:
            return
        try:
            message = self.typestore.deserialize_cdr(cdr, msgtype)
        except Exception as exc:  # whatever a peer sends: one line, never an exception in DDS' thread
            log.warning("%s: cannot deserialise a %s (%d bytes): %s", topic, msgtype, len(cdr), exc)
            return
        try:
            callback(message)
        except Exception as exc:  # e.g. an image that is a decompression bomb: one line, the node goes on
            log.warning("%s: %s: %s", topic, type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")

    def close(self) -> None:
        """Delete the participant (its readers, writers and listener threads) and the domain."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self._announce(present=False)  # as rmw does when a node goes: the participant holds no node
        except Exception as exc:  # closing whatever happened: one line
            log.info("ros_discovery_info: could not announce the node's end (%s)", exc)
        entities, self._entities = self._entities, []
        for entity in (*reversed(entities), self._participant):
            entity.__del__()  # dds_delete now, not when the garbage collector gets to it
        if self._configured:
            _close_domain(self.domain_id)


@dataclass
class _Domain:
    """A domain this process configured, and how many transports use it."""

    domain: _Entity
    users: int = 0


#: The domains this process configured, by domain id.
_DOMAINS: dict[int, _Domain] = {}
_DOMAINS_LOCK = threading.Lock()


def _open_domain(domain_id: int, config: str) -> None:
    """Configure ``domain_id`` with ``config`` once per process (Cyclone allows one configuration per domain: the
    first transport's stands while any uses it)."""
    with _DOMAINS_LOCK:
        if domain_id not in _DOMAINS:
            domain = require("cyclonedds.domain", "semattnet ros2 (DDS)")
            _DOMAINS[domain_id] = _Domain(domain.Domain(domain_id, config))
        _DOMAINS[domain_id].users += 1


def _close_domain(domain_id: int) -> None:
    with _DOMAINS_LOCK:
        entry = _DOMAINS[domain_id]
        entry.users -= 1
        if entry.users == 0:
            del _DOMAINS[domain_id]
            entry.domain.__del__()
