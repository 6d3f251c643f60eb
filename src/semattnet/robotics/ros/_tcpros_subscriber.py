"""A TCPROS subscription: one connection per publisher the master names, each reconnected with backoff while the
master lists it (:class:`Subscription`, :class:`Inbound`; used by :mod:`.tcpros`)."""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from semattnet._errors import SemAttNetError

from ._ros1_xmlrpc import xmlrpc_call
from ._tcpros_wire import (
    CONNECTION_IDS,
    MAX_PEERS,
    TcprosError,
    check_http_uri,
    connect,
    connection_info,
    encode_header,
    read_header,
    read_wire_frame,
    shutdown_socket,
)
from .ros1_types import ros1_type_name

if TYPE_CHECKING:
    from .ros1_types import Ros1Store

__all__ = ["Inbound", "SubscriberNode", "Subscription"]

_log = logging.getLogger("semattnet.robotics.ros.tcpros")
#: Seconds before reconnecting to a publisher, by the number of failed attempts since the last connection.
_RETRY_S = (0.2, 0.5, 1.0, 2.0, 4.0, 8.0)


class Inbound:
    """One publisher of a subscribed topic: ``requestTopic``, connect, handshake, receive; reconnect until stopped."""

    def __init__(self, subscription: Subscription, uri: str) -> None:
        self.sub, self.uri = subscription, uri
        self.stop = threading.Event()
        self.sock: socket.socket | None = None
        self.connection: tuple[int, str] | None = None  # this connection's id and description while it is open
        self.thread = threading.Thread(target=self._run, name=f"tcpros-in{subscription.topic}", daemon=True)

    def _connect(self) -> socket.socket:
        sub = self.sub
        check_http_uri(self.uri, f"{sub.topic}: publisher URI")
        code, status, proto = xmlrpc_call(
            self.uri, "requestTopic", sub.caller_id, sub.topic, [["TCPROS"]], timeout=sub.timeout, stop=self.stop
        )
        if code != 1 or not isinstance(proto, list) or len(proto) != 3 or proto[0] != "TCPROS":
            raise TcprosError(f"requestTopic refused or not TCPROS ({str(status)[:80]!r})")
        if not isinstance(proto[1], str) or not isinstance(proto[2], int) or isinstance(proto[2], bool):
            raise TcprosError(f"requestTopic: {str(proto[1:])[:80]!r} is not a host and a port")
        sock = self.sock = connect(proto[1], proto[2], time.monotonic() + sub.timeout, self.stop)
        sock.sendall(encode_header(sub.fields))
        reply = read_header(sock, sub.timeout, self.stop)
        if "error" in reply:
            raise TcprosError(f"the publisher refused the connection: {reply['error']!r}")
        if reply.get("md5sum") not in (sub.md5sum, "*"):
            raise TcprosError(f"md5sum {reply.get('md5sum')!r} is not {sub.md5sum} ({ros1_type_name(sub.msgtype)})")
        self.connection = (next(CONNECTION_IDS), connection_info(sock))
        return sock

    def _run(self) -> None:
        """Connect and receive; after a failure or a closed connection, retry with backoff until stopped."""
        attempt = 0
        while not self.stop.is_set():
            try:
                sock = self._connect()
                attempt = 0
                limit, timeout = self.sub.max_message_bytes, self.sub.timeout
                while (frame := read_wire_frame(sock, limit, self.stop, timeout)) is not None:
                    self.sub.deliver(frame)
                if not self.stop.is_set():
                    _log.info("%s: publisher %r closed the connection; reconnecting", self.sub.topic, self.uri)
            except (SemAttNetError, OSError) as exc:  # TcprosError, or a URI without a port (InputError)
                self._said(exc, attempt)
                attempt += 1
            except Exception as exc:  # never a traceback from this thread, whatever the peer sent
                self._said(TcprosError(f"{type(exc).__name__}: {str(exc)[:200]}"), attempt)
                attempt += 1
            finally:
                self.connection = None
                if self.sock is not None:
                    self.sock.close()
            self.stop.wait(_RETRY_S[min(attempt, len(_RETRY_S) - 1)])

    def _said(self, exc: BaseException, attempt: int) -> None:
        """One line per outage (the publisher dropped, reconnected through requestTopic); retries are debug lines."""
        if not self.stop.is_set():
            level = logging.WARNING if attempt == 0 else logging.DEBUG
            topic, uri = self.sub.topic, self.uri
            _log.log(level, "%s: publisher %r dropped: %s (reconnecting while the master lists it)", topic, uri, exc)

    def abort(self) -> None:
        """Stop receiving and unblock the thread."""
        self.stop.set()
        shutdown_socket(self.sock)


class SubscriberNode(Protocol):
    """What a subscription reads of its transport (:class:`~.tcpros.TcprosTransport`)."""

    node_name: str
    timeout: float
    max_message_bytes: int

    @property
    def typestore(self) -> Ros1Store: ...

    def _track(self, thread: threading.Thread) -> None: ...


class Subscription:
    """A subscribed topic: one :class:`Inbound` per publisher the master names, following ``publisherUpdate``."""

    def __init__(self, transport: SubscriberNode, topic: str, msgtype: str, callback: Callable[[object], None]) -> None:
        self.topic, self.msgtype, self.callback = topic, msgtype, callback
        self.store = transport.typestore
        self.caller_id, self.timeout = transport.node_name, transport.timeout
        self.max_message_bytes = transport.max_message_bytes
        definition, self.md5sum = self.store.generate_msgdef(msgtype)
        self.fields = {
            "callerid": transport.node_name,
            "topic": topic,
            "type": ros1_type_name(msgtype),
            "md5sum": self.md5sum,
            "message_definition": definition,
            "tcp_nodelay": "1",
        }
        self._track = transport._track
        self._inbound: dict[str, Inbound] = {}
        self._lock = threading.Lock()
        self.closed = False

    def update(self, uris: list[str], drop: bool = True) -> None:
        """Connect to the publishers in ``uris`` not yet connected; drop those no longer listed (if ``drop``)."""
        if len(uris) > MAX_PEERS:
            _log.warning("%s: %d publishers, connecting to the first %d", self.topic, len(uris), MAX_PEERS)
        wanted = uris[:MAX_PEERS]
        with self._lock:
            if self.closed:
                return
            for uri in [u for u in self._inbound if drop and u not in wanted]:
                self._inbound.pop(uri).abort()
            for uri in wanted:
                if uri not in self._inbound or not self._inbound[uri].thread.is_alive():
                    self._inbound[uri] = inbound = Inbound(self, uri)
                    self._track(inbound.thread)

    def bus_info(self) -> list[list[object]]:
        """``getBusInfo``'s rows of this topic's open connections: [connection id, the publisher's URI, "i"
        (inbound), "TCPROS", topic, connected, what the connection is]."""
        with self._lock:
            inbound = list(self._inbound.values())
        rows: list[list[object]] = []
        for peer in inbound:
            if peer.connection is not None:
                cid, info = peer.connection
                rows.append([cid, peer.uri, "i", "TCPROS", self.topic, True, info])
        return rows

    def deliver(self, frame: bytes) -> None:
        """Deserialise one frame and call back; a bad frame or a failing callback is one logged line."""
        try:
            message = self.store.deserialize_ros1(frame, self.msgtype)
        except Exception as exc:
            _log.warning("%s: dropped a message that is not a valid %s (%s)", self.topic, self.msgtype, exc)
            return
        try:
            self.callback(message)
        except Exception as exc:
            _log.warning("%s: the callback failed on a message (%s: %s)", self.topic, type(exc).__name__, exc)

    def abort(self) -> None:
        """Stop every connection."""
        with self._lock:
            self.closed = True
            for inbound in self._inbound.values():
                inbound.abort()
