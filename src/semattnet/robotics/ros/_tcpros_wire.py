"""The ROS 1 wire, bounded: TCPROS connection headers and frames, and XML-RPC with size and time limits.

Everything a peer sends passes through here first: a header or frame longer than its limit, a socket
that stalls past its timeout or an XML-RPC document over :data:`MAX_XMLRPC_BYTES` is a
:class:`TcprosError` (one line), never an unbounded allocation or a blocked thread.
"""

from __future__ import annotations

import http.client
import itertools
import logging
import socket
import struct
import threading
import xmlrpc.client
from collections import deque
from collections.abc import Mapping
from typing import Any
from urllib.parse import urlsplit
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from semattnet._errors import DataError, InputError

__all__ = [
    "CONNECTION_IDS",
    "MAX_HEADER_BYTES",
    "MAX_PEERS",
    "MAX_XMLRPC_BYTES",
    "POLL_S",
    "Outbox",
    "SlaveServer",
    "TcprosError",
    "check_http_uri",
    "connection_info",
    "decode_header",
    "encode_header",
    "read_header",
    "read_wire_frame",
    "shutdown_socket",
    "xmlrpc_call",
]

_log = logging.getLogger(__name__)

#: The longest TCPROS connection header accepted (the largest message definitions are a few tens of KB).
MAX_HEADER_BYTES = 1 << 20
#: The longest XML-RPC request or response accepted (ROS's are a few KB).
MAX_XMLRPC_BYTES = 1 << 20
_LEN = struct.Struct("<I")
#: At most this many connections per topic (subscribers of a publisher, publishers of a subscription).
MAX_PEERS = 64
#: How often waiting threads look whether the transport stops, seconds.
POLL_S = 0.1
#: Connection ids of this process, as rospy numbers its connections for ``getBusInfo`` (from 1).
CONNECTION_IDS = itertools.count(1)


def connection_info(sock: socket.socket) -> str:
    """A connection as rospy describes it in ``getBusInfo`` (``rosnode info`` parses it): ``TCPROS connection on
    port LOCAL to [HOST:PORT on socket FD]``."""
    try:
        host, port = sock.getpeername()[:2]
        return f"TCPROS connection on port {sock.getsockname()[1]} to [{host}:{port} on socket {sock.fileno()}]"
    except OSError:
        return "TCPROS connection (closed)"


class TcprosError(DataError):
    """A ROS 1 peer broke the protocol: a header or frame too long or malformed, a refused handshake, a timeout."""


def check_http_uri(uri: str, what: str) -> tuple[str, int]:
    """``(host, port)`` of an ``http://host:port/`` URI, else an :class:`InputError` naming ``what``."""
    try:
        parts = urlsplit(uri)
        port = parts.port
    except ValueError as exc:
        raise InputError(f"{what}: {uri!r} is not an http://host:port URI ({exc})") from None
    if parts.scheme != "http" or not parts.hostname or port is None:
        raise InputError(f"{what}: {uri!r} is not an http://host:port URI")
    return parts.hostname, port


def encode_header(fields: Mapping[str, str]) -> bytes:
    """A TCPROS connection header: a little-endian length, then ``key=value`` fields, each length-prefixed."""
    body = b"".join(_LEN.pack(len(f)) + f for f in (f"{k}={v}".encode() for k, v in fields.items()))
    return _LEN.pack(len(body)) + body


def decode_header(block: bytes) -> dict[str, str]:
    """The fields of a header body (without its own length prefix); a malformed body is a :class:`TcprosError`."""
    fields: dict[str, str] = {}
    pos = 0
    while pos < len(block):
        if pos + 4 > len(block):
            raise TcprosError("connection header: truncated field length")
        (size,) = _LEN.unpack_from(block, pos)
        field = block[pos + 4 : pos + 4 + size]
        pos += 4 + size
        if len(field) != size or b"=" not in field:
            raise TcprosError("connection header: truncated field or a field without '='")
        key, _, value = field.partition(b"=")
        try:
            fields[key.decode()] = value.decode()
        except UnicodeDecodeError:
            raise TcprosError("connection header: a field is not UTF-8") from None
    return fields


def _recv_exact(sock: socket.socket, size: int, stop: threading.Event | None) -> bytes | None:
    """``size`` bytes from ``sock``; None when the peer closed before the first byte, or ``stop`` is set.

    With ``stop``, a socket timeout only polls it (the socket's timeout is the poll period); without,
    a timeout is a :class:`TcprosError`.
    """
    chunks = bytearray()
    while len(chunks) < size:
        if stop is not None and stop.is_set():
            return None
        try:
            chunk = sock.recv(min(size - len(chunks), 1 << 20))
        except TimeoutError:
            if stop is None:
                raise TcprosError(f"peer sent {len(chunks)} of {size} bytes before the timeout") from None
            continue
        if not chunk:
            if chunks:
                raise TcprosError(f"peer closed the connection after {len(chunks)} of {size} bytes")
            return None
        chunks += chunk
    return bytes(chunks)


def _read_block(sock: socket.socket, limit: int, what: str, stop: threading.Event | None) -> bytes | None:
    """One length-prefixed block of at most ``limit`` bytes; None at a clean end of stream."""
    prefix = _recv_exact(sock, 4, stop)
    if prefix is None:
        return None
    (size,) = _LEN.unpack(prefix)
    if size > limit:
        raise TcprosError(f"{what} of {size} bytes is over the limit of {limit} bytes")
    body = _recv_exact(sock, size, stop)
    if body is None:
        raise TcprosError(f"peer closed the connection before the {what}'s {size} bytes")
    return body


def read_header(sock: socket.socket) -> dict[str, str]:
    """Read one connection header (the socket's timeout bounds the wait); a closed peer is a :class:`TcprosError`."""
    block = _read_block(sock, MAX_HEADER_BYTES, "connection header", None)
    if block is None:
        raise TcprosError("peer closed the connection before its header")
    return decode_header(block)


def read_wire_frame(sock: socket.socket, limit: int, stop: threading.Event) -> bytes | None:
    """One serialised message of at most ``limit`` bytes; None when the peer closed or ``stop`` is set."""
    return _read_block(sock, limit, "message", stop)


class _BoundedTransport(xmlrpc.client.Transport):
    """xmlrpc.client's HTTP transport with a connect/read timeout and a cap on the response's size."""

    def __init__(self, timeout: float) -> None:
        super().__init__()
        self._timeout = timeout

    def make_connection(self, host: str | tuple[str, dict[str, str]]) -> http.client.HTTPConnection:
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn

    def parse_response(self, response: http.client.HTTPResponse) -> tuple[Any, ...]:  # XML-RPC values
        body = response.read(MAX_XMLRPC_BYTES + 1)
        if len(body) > MAX_XMLRPC_BYTES:
            raise TcprosError(f"XML-RPC response over {MAX_XMLRPC_BYTES} bytes")
        parser, unmarshaller = self.getparser()
        parser.feed(body)
        parser.close()
        return unmarshaller.close()


def xmlrpc_call(uri: str, method: str, *args: object, timeout: float) -> list[object]:
    """Call ``method`` on the XML-RPC server at ``uri``; ROS's ``[code, status, value]`` reply, checked for shape.

    Raises :class:`TcprosError` for a reply that is not a 3-list, ``OSError`` for a network failure and
    ``xmlrpc.client.Error`` for an HTTP or XML-RPC fault.
    """
    with xmlrpc.client.ServerProxy(uri, transport=_BoundedTransport(timeout)) as proxy:
        reply = getattr(proxy, method)(*args)
    if not isinstance(reply, list) or len(reply) != 3 or not isinstance(reply[0], int):
        raise TcprosError(f"{uri} {method}: the reply is not [code, status, value]")
    return reply


class _SlaveHandler(SimpleXMLRPCRequestHandler):
    """One XML-RPC request: bounded in time (``timeout``) and size (a missing or large Content-Length is refused)."""

    timeout = 5.0
    rpc_paths = ("/", "/RPC2")

    def do_POST(self) -> None:
        try:
            size = int(self.headers.get("content-length", ""))
        except ValueError:
            size = -1
        if not 0 <= size <= MAX_XMLRPC_BYTES or self.headers.get("content-encoding"):
            self.send_response(413)
            self.send_header("Content-length", "0")
            self.end_headers()
            return
        super().do_POST()

    def log_message(self, format: str, *args: object) -> None:
        """Quiet: the base class writes every request to stderr."""


class SlaveServer(SimpleXMLRPCServer):
    """The node's XML-RPC API (``requestTopic``, ``publisherUpdate``, ...), one request at a time, each bounded."""

    def __init__(self, host: str, timeout: float) -> None:
        handler = type("_TimedSlaveHandler", (_SlaveHandler,), {"timeout": timeout})
        super().__init__((host, 0), requestHandler=handler, logRequests=False, allow_none=False)
        self._thread = threading.Thread(target=self.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)

    @property
    def port(self) -> int:
        """The TCP port it listens on."""
        return int(self.server_address[1])

    def start(self) -> None:
        """Serve from a thread of its own."""
        self._thread.name = f"tcpros-xmlrpc-{self.server_address[1]}"
        self._thread.start()

    def stop(self, timeout: float) -> None:
        """Stop serving and close the socket (waits at most for the request in progress)."""
        if self._thread.is_alive():
            self.shutdown()
            self._thread.join(timeout)
        self.server_close()


class Outbox:
    """One subscriber's connection: a send queue of the QoS depth (drop-oldest) and the thread that empties it."""

    def __init__(self, sock: socket.socket, depth: int, label: str, stop: threading.Event) -> None:
        self._sock = sock
        self._queue: deque[tuple[bytes, memoryview]] = deque(maxlen=max(1, depth))
        self._cond = threading.Condition()
        self._stop = stop
        self.label = label
        self.dropped = 0
        self.alive = True

    def put(self, prefix: bytes, data: memoryview) -> None:
        """Queue one frame; the oldest queued frame is dropped (and counted) when the queue is full."""
        with self._cond:
            if len(self._queue) == self._queue.maxlen:
                self.dropped += 1
            self._queue.append((prefix, data))
            self._cond.notify()

    def run(self) -> None:
        """Send queued frames until the transport stops or the subscriber goes away (the caller's thread)."""
        try:
            while not self._stop.is_set():
                with self._cond:
                    self._cond.wait_for(lambda: self._queue or self._stop.is_set(), timeout=POLL_S)
                    if not self._queue:
                        continue
                    prefix, data = self._queue.popleft()
                self._sock.sendall(prefix)
                self._sock.sendall(data)
        except OSError as exc:
            if not self._stop.is_set():
                _log.info("%s: subscriber connection ended (%s)", self.label, exc)
        finally:
            self.alive = False
            self._sock.close()

    def abort(self) -> None:
        """Unblock a send in progress (close's first step)."""
        shutdown_socket(self._sock)


def shutdown_socket(sock: socket.socket | None) -> None:
    """Unblock every thread reading or writing ``sock`` (an already closed socket is fine)."""
    if sock is not None:
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
