"""The ROS 1 wire, bounded: TCPROS connection headers and frames with size limits and per-call deadlines.

Everything a peer sends over TCPROS passes through here first: a header or frame longer than its limit, or one
that is not whole by its deadline (however slowly the peer drips its bytes), is a :class:`TcprosError` (one
line), never an unbounded allocation or a blocked thread; every wait also polls the transport's stop event.
The XML-RPC side is :mod:`._ros1_xmlrpc`.
"""

from __future__ import annotations

import errno
import itertools
import logging
import os
import selectors
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Mapping
from urllib.parse import urlsplit

from semattnet._errors import DataError, InputError

__all__ = [
    "CONNECTION_IDS",
    "MAX_HEADER_BYTES",
    "MAX_PEERS",
    "MIN_RATE",
    "POLL_S",
    "Outbox",
    "TcprosError",
    "check_http_uri",
    "connect",
    "connection_info",
    "decode_header",
    "encode_header",
    "read_header",
    "read_wire_frame",
    "recv_exact",
    "shutdown_socket",
]

_log = logging.getLogger(__name__)

#: The longest TCPROS connection header accepted (the largest message definitions are a few tens of KB).
MAX_HEADER_BYTES = 1 << 20
#: The slowest a message may arrive once its first byte has (bytes a second): a message of N bytes has the
#: transport's timeout plus N / MIN_RATE seconds to arrive whole, or its publisher is dropped as stalled.
MIN_RATE = 1 << 20
_LEN = struct.Struct("<I")
#: At most this many connections per topic (subscribers of a publisher, publishers of a subscription).
MAX_PEERS = 64
#: How often waiting threads look whether the transport stops, seconds.
POLL_S = 0.1
#: What a non-blocking connect says while it is under way.
_PENDING = (errno.EINPROGRESS, errno.EALREADY, errno.EAGAIN)
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


def recv_exact(sock: socket.socket, size: int, stop: threading.Event | None, deadline: float | None) -> bytes | None:
    """``size`` bytes from ``sock``; None when the peer closed before the first byte, or ``stop`` is set.

    ``deadline`` (``time.monotonic()``) bounds the whole read, however the peer paces its bytes (None: a peer
    may stay silent for ever, as a publisher between messages); past it, a :class:`TcprosError`. Each wait is
    at most :data:`POLL_S`, so ``stop`` is seen within that.
    """
    chunks = bytearray()
    while len(chunks) < size:
        if stop is not None and stop.is_set():
            return None
        left = POLL_S if deadline is None else deadline - time.monotonic()
        if left <= 0:
            raise TcprosError(f"peer sent {len(chunks)} of {size} bytes by the deadline (stalled)")
        sock.settimeout(min(left, POLL_S))
        try:
            chunk = sock.recv(min(size - len(chunks), 1 << 20))
        except TimeoutError:
            continue
        if not chunk:
            if chunks:
                raise TcprosError(f"peer closed the connection after {len(chunks)} of {size} bytes")
            return None
        chunks += chunk
    return bytes(chunks)


def _read_block(
    sock: socket.socket, limit: int, what: str, stop: threading.Event | None, deadline: float | None
) -> bytes | None:
    """One length-prefixed block of at most ``limit`` bytes by ``deadline``; None at a clean end of stream."""
    prefix = recv_exact(sock, 4, stop, deadline)
    if prefix is None:
        return None
    (size,) = _LEN.unpack(prefix)
    if size > limit:
        raise TcprosError(f"{what} of {size} bytes is over the limit of {limit} bytes")
    body = recv_exact(sock, size, stop, deadline)
    if body is None:
        if stop is not None and stop.is_set():
            return None
        raise TcprosError(f"peer closed the connection before the {what}'s {size} bytes")
    return body


def read_header(sock: socket.socket, timeout: float, stop: threading.Event | None = None) -> dict[str, str]:
    """Read one connection header, whole within ``timeout`` seconds; a closed peer is a :class:`TcprosError`."""
    block = _read_block(sock, MAX_HEADER_BYTES, "connection header", stop, time.monotonic() + timeout)
    if block is None:
        raise TcprosError("peer closed the connection before its header")
    return decode_header(block)


def read_wire_frame(sock: socket.socket, limit: int, stop: threading.Event, timeout: float) -> bytes | None:
    """One serialised message of at most ``limit`` bytes; None when the peer closed or ``stop`` is set. The
    wait for its first byte is unbounded; from there it must be whole within ``timeout`` plus its size at
    :data:`MIN_RATE` (a publisher that stalls mid-message is a :class:`TcprosError`)."""
    first = recv_exact(sock, 1, stop, None)
    if first is None:
        return None
    start = time.monotonic()
    rest = recv_exact(sock, 3, stop, start + timeout)
    if rest is None:
        return None
    (size,) = _LEN.unpack(first + rest)
    if size > limit:
        raise TcprosError(f"message of {size} bytes is over the limit of {limit} bytes")
    body = recv_exact(sock, size, stop, start + timeout + size / MIN_RATE)
    if body is None and not stop.is_set():
        raise TcprosError(f"peer closed the connection before the message's {size} bytes")
    return body


def connect(host: str, port: int, deadline: float, stop: threading.Event | None = None) -> socket.socket:
    """A TCP connection to ``host:port`` made by ``deadline`` (``time.monotonic()``), given up as soon as ``stop``
    is set; a :class:`TcprosError` (one line) for a port out of range, a refusal or the deadline."""
    if not 0 < port < 65536:
        raise TcprosError(f"port {port} is not a TCP port")
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except (OSError, UnicodeError, ValueError) as exc:
        raise TcprosError(f"cannot resolve {host!r} ({exc})") from None
    sock = socket.socket(family, kind, proto)
    try:
        sock.setblocking(False)
        err = sock.connect_ex(address)
        with selectors.DefaultSelector() as selector:
            selector.register(sock, selectors.EVENT_WRITE)
            while err in _PENDING and not selector.select(POLL_S):
                if (stop is not None and stop.is_set()) or time.monotonic() > deadline:
                    raise TcprosError(f"no connection to {host}:{port} by the deadline")
            err = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) if err else 0
        if err:
            raise TcprosError(f"cannot connect to {host}:{port} ({os.strerror(err)})")
    except BaseException:
        sock.close()
        raise
    sock.settimeout(max(deadline - time.monotonic(), POLL_S))  # a send's bound; reads set their own
    return sock


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
