"""ROS 1 without rospy: a :class:`~.transport.Transport` that speaks the master's XML-RPC and TCPROS itself.

A ROS 1 node is an XML-RPC client of the master (``registerPublisher``, ``registerSubscriber``,
``unregister*``), an XML-RPC server for its peers (``requestTopic``, ``publisherUpdate``, ``getPid``,
``shutdown``, ...) and, per topic, TCP connections that open with a header exchange (the type's name,
md5sum and message definition) and then carry 4-byte length-prefixed ROS 1 serialised messages. The
messages are ``rosbags`` objects of the ROS 1 Noetic type store (:attr:`TcprosTransport.typestore`);
objects of a ROS 2 store are converted field by field (a missing ``Header.seq`` is 0).

Bounded: every connect, handshake, message and XML-RPC call has a deadline (however slowly a peer drips its
bytes; a publisher that stalls mid-message is dropped and reconnected) and every wait polls the stop event;
each subscriber connection has its own send queue of the QoS depth that drops the oldest message (a slow
subscriber never blocks :meth:`TcprosPublisher.publish`); headers, frames and XML-RPC documents have size
limits; at most :data:`MAX_PEERS` connections per topic. A malformed handshake or message, or a hostile peer's
reply, is one logged line naming the topic, and :meth:`TcprosTransport.close` ends every thread and socket
within about a second (:data:`UNREGISTER_S` for the master, :data:`JOIN_S` for the threads). A
subscriber reconnects to a publisher whose connection dropped (with backoff) while the master lists it;
``subscribe``'s callback runs on that connection's thread.

Example (needs a running ``roscore``)::

    transport = TcprosTransport("http://127.0.0.1:11311", "/semattnet", "127.0.0.1")
    depth = transport.advertise("/semattnet/depth_image", "sensor_msgs/msg/Image", OUTPUT_QOS)
    depth.publish(message)  # a rosbags sensor_msgs/msg/Image of transport.typestore
    transport.close()
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
import socket
import struct
import threading
import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, cast

from semattnet._errors import InputError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

from ..bags.deps import rosbags_typestore
from ._ros1_xmlrpc import SlaveServer, xmlrpc_call
from ._tcpros_subscriber import Subscription
from ._tcpros_wire import (
    CONNECTION_IDS,
    MAX_PEERS,
    POLL_S,
    Outbox,
    TcprosError,
    check_http_uri,
    connection_info,
    encode_header,
    read_header,
)
from .ros1_types import Ros1Store, adopt_message, ros1_type_name, store_type_name
from .transport import QoS

__all__ = [
    "DEFAULT_MAX_MESSAGE_BYTES",
    "MAX_PEERS",
    "TcprosError",
    "TcprosPublisher",
    "TcprosTransport",
    "adopt_message",
    "ros1_type_name",
]

_log = logging.getLogger(__name__)

#: The longest message accepted from a publisher (a 4K 32FC1 image is 33 MB).
DEFAULT_MAX_MESSAGE_BYTES = 1 << 28
#: Seconds :meth:`TcprosTransport.close` gives the master, all unregister calls together (SIGINT ends the node
#: within 2 s whatever the master does), and then the transport's threads.
UNREGISTER_S = 0.5
JOIN_S = 0.5
_LEN = struct.Struct("<I")
_NAME = re.compile(r"/[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")
_MISSING = object()


class TcprosPublisher:
    """One advertised topic (:class:`~.transport.Publisher`): serialises once, queues to every subscriber.

    A durable QoS (transient local, as ``/tf_static`` is published) makes it a latched topic, as ROS 1 has them:
    a subscriber that connects later gets the last message first."""

    def __init__(self, store: Ros1Store, caller_id: str, topic: str, msgtype: str, qos: QoS) -> None:
        self.topic, self.msgtype, self.qos = topic, msgtype, qos
        self._store = store
        definition, self.md5sum = store.generate_msgdef(msgtype)
        self.fields = {
            "callerid": caller_id,
            "topic": topic,
            "type": ros1_type_name(msgtype),
            "md5sum": self.md5sum,
            "message_definition": definition,
            "latching": "1" if qos.durable else "0",
        }
        self._outboxes: list[Outbox] = []
        self._peers: dict[Outbox, tuple[int, str, str]] = {}  # connection id, the subscriber's caller id, its info
        self._latched: tuple[bytes, memoryview] | None = None  # a durable topic's last message, for late subscribers
        self._lock = threading.Lock()
        self._dropped_gone = 0
        self._seq = 0

    @property
    def dropped(self) -> int:
        """Messages dropped so far because a subscriber's queue was full (a slow subscriber)."""
        with self._lock:
            return self._dropped_gone + sum(o.dropped for o in self._outboxes)

    @property
    def subscriber_count(self) -> int:
        """How many subscriber connections are open."""
        with self._lock:
            return sum(o.alive for o in self._outboxes)

    def publish(self, message: object) -> None:
        """Serialise ``message`` (a rosbags ``msgtype`` object) once and queue it to every subscriber; never blocks.
        A ``Header.seq`` is this topic's count of messages, from 1, as rospy numbers them (``message`` is kept)."""
        try:
            data = self._store.serialize_ros1(self._numbered(adopt_message(self._store, message)), self.msgtype)
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"{self.topic}: cannot serialise the message as {self.msgtype} ({exc})") from None
        prefix = _LEN.pack(len(data))
        with self._lock:
            if self.qos.durable:
                self._latched = (prefix, data)
            self._dropped_gone += sum(o.dropped for o in self._outboxes if not o.alive)
            self._outboxes = [o for o in self._outboxes if o.alive]
            outboxes = list(self._outboxes)
        for outbox in outboxes:
            outbox.put(prefix, data)

    def _numbered(self, message: object) -> object:
        """``message`` with the next ``header.seq`` (a copy of it and its header; unchanged without a header)."""
        header: object = getattr(message, "header", None)
        if not hasattr(header, "seq") or not dataclasses.is_dataclass(message) or isinstance(message, type):
            return message
        with self._lock:
            self._seq += 1
            seq = self._seq
        numbered = dataclasses.replace(cast("DataclassInstance", header), seq=seq)
        return dataclasses.replace(message, header=numbered)

    def bus_info(self) -> list[list[object]]:
        """``getBusInfo``'s rows of this topic's open connections, as rospy gives them: [connection id, the
        subscriber's caller id, "o" (outbound), "TCPROS", topic, connected, what the connection is]."""
        with self._lock:
            peers = [self._peers[o] for o in self._outboxes if o.alive and o in self._peers]
        return [[cid, caller, "o", "TCPROS", self.topic, True, info] for cid, caller, info in peers]

    def attach(self, sock: socket.socket, label: str, stop: threading.Event, caller: str = "") -> Outbox | None:
        """A new subscriber's outbox (``caller``: its caller id), or None (the socket closed) beyond
        :data:`MAX_PEERS` connections."""
        with self._lock:
            if sum(o.alive for o in self._outboxes) >= MAX_PEERS:
                _log.warning("%s: refused %s: already %d subscribers", self.topic, label, MAX_PEERS)
                sock.close()
                return None
            outbox = Outbox(sock, self.qos.depth, f"{self.topic} -> {label}", stop)
            if self._latched is not None:
                outbox.put(*self._latched)
            self._outboxes.append(outbox)
            self._peers = {o: p for o, p in self._peers.items() if o.alive}
            self._peers[outbox] = (next(CONNECTION_IDS), caller or label, connection_info(sock))
            return outbox

    def abort(self) -> None:
        """Unblock every send in progress."""
        with self._lock:
            for outbox in self._outboxes:
                outbox.abort()


class TcprosTransport:
    """A ROS 1 node's transport (:class:`~.transport.Transport`): master XML-RPC, a slave API and TCPROS.

    ``master_uri`` is the ROS master (``ROS_MASTER_URI``), ``node_name`` the node's caller id,
    ``host`` the address peers reach this node at (default ``ROS_IP``, else ``ROS_HOSTNAME``, else
    127.0.0.1); ``timeout`` bounds each connect, handshake and XML-RPC call, whole (a deadline, not a
    read's timeout); ``on_shutdown`` is called when a peer calls ``shutdown``. The master must be
    reachable: the constructor checks it.
    """

    name = "tcpros"

    def __init__(
        self,
        master_uri: str,
        node_name: str = "/semattnet",
        host: str | None = None,
        *,
        timeout: float = 5.0,
        max_message_bytes: int = DEFAULT_MAX_MESSAGE_BYTES,
        on_shutdown: Callable[[], object] | None = None,
    ) -> None:
        check_http_uri(master_uri, "ROS master URI")
        self.on_shutdown = on_shutdown
        self.node_name = "/" + node_name.strip("/")
        if not _NAME.fullmatch(self.node_name):
            raise InputError(f"ROS node name {node_name!r}: expected letters, digits, '_' and '/'")
        self.master_uri, self.timeout, self.max_message_bytes = master_uri, timeout, max_message_bytes
        self.host = host or os.environ.get("ROS_IP") or os.environ.get("ROS_HOSTNAME") or "127.0.0.1"
        self.typestore = cast(Ros1Store, rosbags_typestore(True))  # rosbags' Typestore has these too
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._publishers: dict[str, TcprosPublisher] = {}
        self._subscriptions: dict[str, Subscription] = {}
        self._threads: list[threading.Thread] = []
        self._closed = False
        self._done = threading.Event()  # set when close() has ended everything
        try:
            self._listener = socket.create_server((self.host, 0))
        except OSError as exc:
            raise InputError(f"ROS host {self.host!r} (ROS_IP): cannot listen there ({exc})") from None
        self._listener.settimeout(POLL_S)
        self._slave = SlaveServer(self.host, timeout)
        self._register_api()
        try:
            self._master("getUri")
        except TcprosError:
            self._listener.close()
            self._slave.server_close()
            raise
        self._slave.start()
        self._track(threading.Thread(target=self._accept_loop, name="tcpros-accept", daemon=True))

    @property
    def uri(self) -> str:
        """This node's XML-RPC URI (what the master and peers call)."""
        return f"http://{self.host}:{self._slave.port}/"

    def advertise(self, topic: str, msgtype: str, qos: QoS) -> TcprosPublisher:
        """Register ``topic`` of ``msgtype`` with the master and accept its subscribers."""
        typename = self._check(topic, msgtype)
        with self._lock:
            known = self._publishers.get(topic)
            if known is not None:
                if known.msgtype != typename:
                    raise InputError(f"{topic}: already advertised as {known.msgtype}, not {typename}")
                return known
            publisher = self._publishers[topic] = TcprosPublisher(self.typestore, self.node_name, topic, typename, qos)
        try:
            self._master("registerPublisher", topic, ros1_type_name(typename), self.uri)
        except BaseException:
            with self._lock:
                del self._publishers[topic]
            raise
        return publisher

    def subscribe(self, topic: str, msgtype: str, qos: QoS, callback: Callable[[object], None]) -> None:
        """Register ``topic`` with the master, connect to its publishers; ``callback`` gets each message."""
        typename = self._check(topic, msgtype)
        with self._lock:
            if topic in self._subscriptions:
                raise InputError(f"{topic}: already subscribed")
            subscription = self._subscriptions[topic] = Subscription(self, topic, typename, callback)
        try:
            publishers = self._master("registerSubscriber", topic, ros1_type_name(typename), self.uri)
        except BaseException:
            with self._lock:
                del self._subscriptions[topic]
            raise
        # Additive: a publisherUpdate that raced ahead of this reply is newer than it.
        listed = [uri for uri in publishers if isinstance(uri, str)] if isinstance(publishers, list) else []
        subscription.update(listed, drop=False)

    def close(self) -> None:
        """Unregister from the master, stop the servers, end every connection and thread (bounded; idempotent)."""
        with self._lock:
            closing, self._closed = self._closed, True
        if closing:  # closing or closed already (a remote shutdown, say): wait for it to finish
            self._done.wait(self.timeout + 2.0)
            return
        self._unregister_all()
        self._stop.set()
        self._slave.stop()
        for publisher in self._publishers.values():
            publisher.abort()
        for subscription in self._subscriptions.values():
            subscription.abort()
        deadline = time.monotonic() + JOIN_S  # every wait polls the stop event: they end within POLL_S
        with self._lock:
            threads = list(self._threads)
        for thread in threads:
            if thread is not threading.current_thread():
                thread.join(max(0.0, deadline - time.monotonic()))
        self._listener.close()
        self._done.set()

    def __enter__(self) -> TcprosTransport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check(self, topic: str, msgtype: str) -> str:
        """The type store's name of ``msgtype``, after checking the topic name and the type."""
        if not _NAME.fullmatch(topic):
            raise InputError(f"ROS topic {topic!r}: expected an absolute name such as /camera/image_raw")
        typename = store_type_name(msgtype)
        if typename not in self.typestore.types:
            raise InputError(f"{topic}: message type {msgtype!r} is not a ROS 1 Noetic type")
        if self._closed:
            raise InputError(f"{topic}: the ROS 1 transport is closed")
        return typename

    def _master(self, method: str, *args: object) -> object:
        """Call the master as this node: its value, or a :class:`TcprosError` (unreachable, or a failure code)."""
        try:
            code, status, value = xmlrpc_call(
                self.master_uri, method, self.node_name, *args, timeout=self.timeout, stop=self._stop
            )
        except TcprosError as exc:
            raise TcprosError(f"ROS master {self.master_uri} {method}: {exc}") from None
        if code != 1:
            raise TcprosError(f"ROS master {self.master_uri} {method}: {status!r}")
        return value

    def _unregister_all(self) -> None:
        """Unregister every topic within :data:`UNREGISTER_S` in all; a master too slow for that is one line."""
        calls = [("unregisterPublisher", t) for t in self._publishers]
        calls += [("unregisterSubscriber", t) for t in self._subscriptions]
        deadline = time.monotonic() + UNREGISTER_S
        for done, (method, topic) in enumerate(calls):
            left = deadline - time.monotonic()
            if left > 0:
                try:
                    xmlrpc_call(self.master_uri, method, self.node_name, topic, self.uri, timeout=left)
                    continue
                except TcprosError as exc:
                    if time.monotonic() < deadline:
                        _log.info("%s: %s failed (%s)", topic, method, exc)
                        continue
            _log.warning(
                "ROS master %s: no answer to unregister within %g s; %d topic(s) left registered (the master drops "
                "them when it next finds this node gone)",
                self.master_uri,
                UNREGISTER_S,
                len(calls) - done,
            )
            return

    def _track(self, thread: threading.Thread) -> None:
        """Start ``thread`` and remember it for close (forgetting finished ones)."""
        with self._lock:
            self._threads = [t for t in self._threads if t.is_alive()]
            self._threads.append(thread)
        thread.start()

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                sock, address = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            if sum(t.is_alive() for t in self._threads) > MAX_PEERS * (1 + len(self._publishers)):
                _log.warning("tcpros: refused a connection from %s: too many connections", address[0])
                sock.close()
                continue
            label = f"{address[0]}:{address[1]}"
            self._track(threading.Thread(target=self._serve, args=(sock, label), name="tcpros-out", daemon=True))

    def _serve(self, sock: socket.socket, label: str) -> None:
        """A subscriber's connection: the handshake (bounded, checked), then its outbox until it ends."""
        sock.settimeout(self.timeout)
        try:
            request = read_header(sock, self.timeout, self._stop)
            sock.settimeout(self.timeout)  # each send's bound from here
            publisher = self._publishers.get(request.get("topic", ""))
            error = self._refusal(request, publisher)
            if error or publisher is None:
                _log.warning("tcpros: refused subscriber %s (%r): %s", label, request.get("callerid", "?"), error)
                sock.sendall(encode_header({"error": error}))
                sock.close()
                return
            sock.sendall(encode_header(publisher.fields))
        except (TcprosError, OSError) as exc:
            _log.warning("tcpros: handshake with %s failed: %s", label, exc)
            sock.close()
            return
        if request.get("probe") == "1":
            sock.close()
            return
        if request.get("tcp_nodelay") == "1":
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        caller = str(request.get("callerid", label))
        outbox = publisher.attach(sock, repr(caller), self._stop, caller)
        if outbox is not None:
            outbox.run()

    @staticmethod
    def _refusal(request: Mapping[str, str], publisher: TcprosPublisher | None) -> str:
        """Why a subscriber's header is refused ("" if it is not)."""
        if publisher is None:
            return f"topic {request.get('topic')!r} is not published by this node"
        if request.get("md5sum") not in ("*", publisher.md5sum):
            return f"md5sum {request.get('md5sum')!r} is not {publisher.md5sum} ({publisher.fields['type']})"
        return ""

    def _register_api(self) -> None:
        """The slave API peers and the master call (ROS's Slave API; each reply is [code, status, value])."""
        api: dict[str, Callable[..., list[object]]] = {
            "getBusStats": lambda caller: [1, "", [[], [], []]],
            "getBusInfo": lambda caller: [1, "bus info", self.bus_info()],
            "getMasterUri": lambda caller: [1, "", self.master_uri],
            "getPid": lambda caller: [1, "", os.getpid()],
            "getPublications": lambda caller: [1, "", [[t, p.fields["type"]] for t, p in self._publishers.items()]],
            "getSubscriptions": lambda caller: [
                1,
                "",
                [[t, ros1_type_name(s.msgtype)] for t, s in self._subscriptions.items()],
            ],
            "paramUpdate": lambda caller, key, value: [1, "", 0],
            "publisherUpdate": self._publisher_update,
            "requestTopic": self._request_topic,
            "shutdown": self._remote_shutdown,
        }
        for method, function in api.items():
            self._slave.register_function(function, method)

    def bus_info(self) -> list[list[object]]:
        """The node's connections as rospy's ``getBusInfo`` lists them (``rosnode info``): outbound ones per
        published topic, inbound ones per subscribed topic (the publisher's URI as the destination)."""
        with self._lock:
            publishers, subscriptions = list(self._publishers.values()), list(self._subscriptions.values())
        rows = [row for p in publishers for row in p.bus_info()]
        return rows + [row for s in subscriptions for row in s.bus_info()]

    def _publisher_update(self, caller: str, topic: str, publishers: object) -> list[object]:
        subscription = self._subscriptions.get(topic)
        if subscription is None or not isinstance(publishers, list):
            return [0, f"not a subscriber of {topic!r}", 0]
        subscription.update([uri for uri in publishers if isinstance(uri, str)])
        return [1, "", 0]

    def _request_topic(self, caller: str, topic: str, protocols: list[object]) -> list[object]:
        if topic not in self._publishers:
            return [-1, f"not a publisher of {topic!r}", []]
        if not any(isinstance(p, list) and p[:1] == ["TCPROS"] for p in protocols):
            return [0, "no supported protocol (this node speaks TCPROS)", []]
        return [1, "", ["TCPROS", self.host, self._listener.getsockname()[1]]]

    def _remote_shutdown(self, caller: object, message: object = "") -> list[object]:
        """The ``shutdown`` call (``rosnode kill``; roscore on a node-name clash): one line naming the caller and its
        reason, the transport closed and ``on_shutdown`` told (the CLI: the node stops as on SIGTERM)."""
        said = (str(caller)[:200], str(message)[:200])
        _log.warning("ROS 1: %r asked this node to shut down (%r); stopping", *said)
        threading.Thread(target=self.close, name="tcpros-shutdown", daemon=True).start()
        if self.on_shutdown is not None:
            self.on_shutdown()
        return [1, "", 0]
