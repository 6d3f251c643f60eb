"""ROS 1's XML-RPC, bounded: a client whose every call has one deadline, and the node's threaded slave API.

:func:`xmlrpc_call` speaks HTTP itself so that one deadline bounds the whole call (connect, send, the reply's
every byte), however slowly the peer drips its reply; it gives up as soon as the transport stops, and every
failure (a refusal, the deadline, an HTTP error page, garbage XML, a fault, a reply of the wrong shape) is
one :class:`~._tcpros_wire.TcprosError` line. :class:`SlaveServer` answers each connection on a thread of
its own: at most :data:`MAX_XMLRPC_CLIENTS` at once, each dropped when it has not been answered within the
transport's timeout, so one peer dripping bytes into the port holds no other caller.
"""

from __future__ import annotations

import logging
import socket
import socketserver
import threading
import time
import xmlrpc.client
from typing import Any, cast
from urllib.parse import urlsplit
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from semattnet._errors import InputError

from ._tcpros_wire import POLL_S, TcprosError, check_http_uri, connect, shutdown_socket

__all__ = ["MAX_XMLRPC_BYTES", "MAX_XMLRPC_CLIENTS", "SlaveServer", "xmlrpc_call"]

_log = logging.getLogger("semattnet.robotics.ros.tcpros")

#: The longest XML-RPC request or response accepted (ROS's are a few KB).
MAX_XMLRPC_BYTES = 1 << 20
#: The longest HTTP status line and headers accepted before a reply's body.
_MAX_HEAD_BYTES = 16 << 10
#: At most this many connections to the slave API at once (a connection beyond is closed unanswered).
MAX_XMLRPC_CLIENTS = 32


def _said(text: object, size: int = 80) -> str:
    """A peer's text as a log line may hold it: quoted (no line breaks), cut to ``size`` characters."""
    return repr(str(text)[:size])


def xmlrpc_call(
    uri: str, method: str, *args: object, timeout: float, stop: threading.Event | None = None
) -> list[object]:
    """Call ``method`` on the XML-RPC server at ``uri`` within ``timeout`` seconds in all: ROS's ``[code, status,
    value]`` reply, checked for shape. Every failure is a :class:`TcprosError` (one line), also when ``stop``
    is set meanwhile."""
    try:
        host, port = check_http_uri(uri, "XML-RPC URI")
    except InputError as exc:
        raise TcprosError(str(exc)) from None
    deadline = time.monotonic() + timeout
    body = xmlrpc.client.dumps(cast("tuple[Any, ...]", args), method, allow_none=False).encode()
    path = urlsplit(uri).path or "/"
    head = f"POST {path} HTTP/1.0\r\nHost: {host}:{port}\r\nContent-Type: text/xml\r\nContent-Length: {len(body)}"
    try:
        with connect(host, port, deadline, stop) as sock:
            sock.sendall(head.encode() + b"\r\n\r\n" + body)
            reply = _http_body(_receive(sock, deadline, stop, timeout))
    except OSError as exc:
        raise TcprosError(f"{exc.strerror or exc}") from None
    return _checked_reply(reply, uri, method)


def _receive(sock: socket.socket, deadline: float, stop: threading.Event | None, timeout: float) -> bytes:
    """An HTTP reply, whole (its Content-Length, else to the end of the stream) by ``deadline``."""
    data = bytearray()
    while not _whole(data):
        if stop is not None and stop.is_set():
            raise TcprosError("the transport stopped before the reply")
        left = deadline - time.monotonic()
        if left <= 0:
            raise TcprosError(f"no whole reply within {timeout:g} s ({len(data)} bytes came)")
        sock.settimeout(min(left, POLL_S))
        try:
            chunk = sock.recv(1 << 16)
        except TimeoutError:
            continue
        if not chunk:
            break
        data += chunk
        if len(data) > MAX_XMLRPC_BYTES + _MAX_HEAD_BYTES:
            raise TcprosError(f"XML-RPC response over {MAX_XMLRPC_BYTES} bytes")
    return bytes(data)


def _length(head: bytes) -> int | None:
    """The Content-Length an HTTP head names (None: none, or not a number)."""
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            return int(value) if value.strip().isdigit() else None
    return None


def _whole(data: bytes | bytearray) -> bool:
    """Whether ``data`` holds an HTTP head and the Content-Length bytes of body it names."""
    head, sep, body = bytes(data).partition(b"\r\n\r\n")
    length = _length(head) if sep else None
    return length is not None and len(body) >= length


def _http_body(data: bytes) -> bytes:
    """The body of an HTTP 200 reply; anything else (an error page, not HTTP, cut short) is a :class:`TcprosError`."""
    head, sep, body = data.partition(b"\r\n\r\n")
    status = head.split(b"\r\n", 1)[0].split(None, 2)
    if not sep or len(status) < 2 or not status[0].startswith(b"HTTP/"):
        raise TcprosError(f"not an HTTP reply ({_said(data[:40])})" if data else "the peer closed without a reply")
    if status[1] != b"200":
        reason = status[2].decode("latin-1") if len(status) > 2 else ""
        raise TcprosError(f"HTTP {_said(status[1].decode('latin-1'), 8)} {_said(reason)}")
    length = _length(head)
    if length is not None and len(body) < length:
        raise TcprosError(f"the reply was cut short ({len(body)} of {length} bytes)")
    if len(body) > MAX_XMLRPC_BYTES:
        raise TcprosError(f"XML-RPC response over {MAX_XMLRPC_BYTES} bytes")
    return body if length is None else body[:length]


def _checked_reply(body: bytes, uri: str, method: str) -> list[object]:
    """The ``[code, status, value]`` of an XML-RPC reply, else a :class:`TcprosError` (a fault, garbage XML)."""
    try:
        params, _ = xmlrpc.client.loads(body)
    except xmlrpc.client.Fault as fault:
        raise TcprosError(f"XML-RPC fault {_said(fault.faultCode, 12)}: {_said(fault.faultString)}") from None
    except Exception as exc:  # expat's errors, a bad number or date: the parser raises many kinds
        raise TcprosError(f"not an XML-RPC reply ({type(exc).__name__}: {_said(exc)})") from None
    reply = params[0] if len(params) == 1 else None
    if not isinstance(reply, list) or len(reply) != 3 or not isinstance(reply[0], int):
        raise TcprosError(f"{uri} {method}: the reply is not [code, status, value]")
    return reply


class _SlaveHandler(SimpleXMLRPCRequestHandler):
    """One XML-RPC request: bounded in time (``timeout`` a read; the server bounds the whole) and size (a missing
    or large Content-Length is refused)."""

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


class SlaveServer(socketserver.ThreadingMixIn, SimpleXMLRPCServer):
    """The node's XML-RPC API (``requestTopic``, ``publisherUpdate``, ...): each connection on its own thread, at
    most :data:`MAX_XMLRPC_CLIENTS` at once, each closed when it is not answered within ``timeout`` seconds."""

    daemon_threads = True
    block_on_close = False
    request_queue_size = 64  # a burst of callers waits in the kernel's queue, not in SYN retries

    def __init__(self, host: str, timeout: float) -> None:
        handler = type("_TimedSlaveHandler", (_SlaveHandler,), {"timeout": timeout})
        super().__init__((host, 0), requestHandler=handler, logRequests=False, allow_none=False)
        self.request_s = timeout
        self._active: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._refusing = False
        self._thread = threading.Thread(target=self.serve_forever, kwargs={"poll_interval": POLL_S}, daemon=True)

    @property
    def port(self) -> int:
        """The TCP port it listens on."""
        return int(self.server_address[1])

    def start(self) -> None:
        """Serve from a thread of its own."""
        self._thread.name = f"tcpros-xmlrpc-{self.server_address[1]}"
        self._thread.start()

    def process_request(self, request: socket.socket, client_address: object) -> None:  # type: ignore[override]
        """A connection's thread, or the connection closed unanswered beyond :data:`MAX_XMLRPC_CLIENTS`."""
        with self._lock:
            full = len(self._active) >= MAX_XMLRPC_CLIENTS
            said, self._refusing = self._refusing, full
            if not full:
                self._active.add(request)
        if full:
            if not said:  # one line per burst
                _log.warning("tcpros: XML-RPC API: %d connections open, refusing more", MAX_XMLRPC_CLIENTS)
            self.shutdown_request(request)
            return
        super().process_request(request, client_address)

    def process_request_thread(self, request: socket.socket, client_address: object) -> None:  # type: ignore[override]
        """Answer one connection; at ``timeout`` seconds it is closed, answered or not."""
        timer = threading.Timer(self.request_s, shutdown_socket, (request,))
        timer.daemon = True
        timer.start()
        try:
            super().process_request_thread(request, client_address)
        finally:
            timer.cancel()
            with self._lock:
                self._active.discard(request)

    def handle_error(self, request: object, client_address: object) -> None:
        """A connection that broke mid-request (dropped at its deadline, reset): a debug line, not a traceback."""
        _log.debug("tcpros: XML-RPC API: a connection from %s ended mid-request", client_address)

    def stop(self) -> None:
        """Stop serving, close every connection still open and the socket (bounded by the poll period)."""
        if self._thread.is_alive():
            self.shutdown()
            self._thread.join(1.0)
        with self._lock:
            for request in self._active:
                shutdown_socket(request)
        self.server_close()
