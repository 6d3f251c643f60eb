"""ROS 1 peers that misbehave, for the deadline and hostile-peer tests: a master that drips its replies to chosen
methods one byte at a time, a server that answers every request with fixed bytes (garbage XML, an HTML page), and
a publisher whose TCPROS side handshakes and then does what the test says."""

from __future__ import annotations

import socket
import socketserver
import struct
import threading
import time
import xmlrpc.client
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from semattnet.robotics.ros._tcpros_wire import encode_header

from ._ros1_master import serve_master_api


def drip(conn: socket.socket, data: bytes, period: float, stop: threading.Event) -> None:
    """Send ``data`` one byte every ``period`` seconds until it is sent, the peer goes or ``stop`` is set."""
    for i in range(len(data)):
        if stop.wait(period):
            return
        try:
            conn.sendall(data[i : i + 1])
        except OSError:
            return


class _MasterHandler(SimpleXMLRPCRequestHandler):
    def do_POST(self) -> None:
        master: ThreadedMaster = self.server.master  # type: ignore[attr-defined]
        body = self.rfile.read(int(self.headers.get("content-length", "0")))
        method = xmlrpc.client.loads(body)[1] or ""
        if method in master.drip:
            master.dripped.append(method)
            head = b"HTTP/1.0 200 OK\r\nContent-Type: text/xml\r\nContent-Length: 100000\r\n\r\n"
            drip(self.connection, head + b" " * 100_000, master.period, master.stop)
            return
        reply = master.canned.get(method)
        if reply is None:
            body = self.server._marshaled_dispatch(body)  # type: ignore[attr-defined]
            reply = b"HTTP/1.0 200 OK\r\nContent-Type: text/xml\r\nContent-Length: %d\r\n\r\n" % len(body) + body
        self.wfile.write(reply)

    def log_message(self, format: str, *args: object) -> None:
        pass


class _Server(socketserver.ThreadingMixIn, SimpleXMLRPCServer):
    daemon_threads = True
    block_on_close = False


class ThreadedMaster:
    """The Master API a node uses, each call on its own thread; the methods in ``drip`` answer one byte every
    ``period`` seconds, those in ``canned`` with those raw bytes (an HTTP reply of the test's making)."""

    def __init__(self, drip: frozenset[str] = frozenset(), period: float = 2.0) -> None:
        self.drip, self.period = drip, period
        self.canned: dict[str, bytes] = {}
        self.dripped: list[str] = []
        self.stop = threading.Event()
        self.publishers: dict[str, list[str]] = {}
        self.apis: list[str] = []
        self._server = _Server(("127.0.0.1", 0), requestHandler=_MasterHandler, logRequests=False)
        self._server.master = self  # type: ignore[attr-defined]
        self._thread = serve_master_api(self, self._server)

    @property
    def uri(self) -> str:
        return f"http://127.0.0.1:{self._server.server_address[1]}/"

    def registerPublisher(self, caller: str, topic: str, msgtype: str, api: str) -> list[Any]:
        self.apis.append(api)
        return [1, "", []]

    def registerSubscriber(self, caller: str, topic: str, msgtype: str, api: str) -> list[Any]:
        self.apis.append(api)
        return [1, "", list(self.publishers.get(topic, []))]

    def unregisterPublisher(self, caller: str, topic: str, api: str) -> list[Any]:
        return [1, "", 1]

    def unregisterSubscriber(self, caller: str, topic: str, api: str) -> list[Any]:
        return [1, "", 1]

    def close(self) -> None:
        self.stop.set()
        self._server.shutdown()
        self._thread.join(5)
        self._server.server_close()


@contextmanager
def threaded_master(drip: frozenset[str] = frozenset(), period: float = 2.0) -> Iterator[ThreadedMaster]:
    master = ThreadedMaster(drip, period)
    try:
        yield master
    finally:
        master.close()


@contextmanager
def _serving(handle: Callable[[socket.socket], None]) -> Iterator[int]:
    """A listener on 127.0.0.1 whose every connection ``handle`` gets, from a thread until the block ends; its port."""
    listener = socket.create_server(("127.0.0.1", 0))
    listener.settimeout(0.1)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            handle(conn)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield listener.getsockname()[1]
    finally:
        stop.set()
        listener.close()
        thread.join(5)


@contextmanager
def raw_http(reply: bytes | Callable[[socket.socket], None]) -> Iterator[str]:
    """A server on 127.0.0.1 answering every connection with ``reply`` (bytes, or what a function sends) once it
    has read the request's first bytes; its URI."""

    def answer(conn: socket.socket) -> None:
        with conn:
            conn.settimeout(2)
            try:
                conn.recv(65536)
                reply(conn) if callable(reply) else conn.sendall(reply)
            except OSError:
                pass

    with _serving(answer) as port:
        yield f"http://127.0.0.1:{port}/"


def xmlrpc_reply(value: object) -> bytes:
    """A whole HTTP 200 reply carrying ``value`` as XML-RPC."""
    body = xmlrpc.client.dumps((value,), methodresponse=True).encode()
    return b"HTTP/1.0 200 OK\r\nContent-Length: %d\r\n\r\n" % len(body) + body


@contextmanager
def tcpros_publisher(
    md5sum: str, then: Callable[[socket.socket, int], None], header: bytes | None = None
) -> Iterator[tuple[str, list[int]]]:
    """A publisher: ``requestTopic`` names its TCP port; each connection is answered with ``header`` (default: a
    good one of ``md5sum``), then ``then(conn, n)`` (n: the connection's number, from 0) runs. Its URI and the
    list of the connections' numbers so far."""
    connections: list[int] = []
    good = encode_header({"md5sum": md5sum, "type": "sensor_msgs/Image", "callerid": "/fake"})

    def accept(conn: socket.socket) -> None:
        connections.append(len(connections))
        threading.Thread(target=talk, args=(conn, connections[-1]), daemon=True).start()

    def talk(conn: socket.socket, n: int) -> None:
        with conn:
            try:
                conn.recv(65536)
                conn.sendall(good if header is None else header)
                then(conn, n)
            except OSError:
                pass

    with _serving(accept) as port, raw_http(xmlrpc_reply([1, "", ["TCPROS", "127.0.0.1", port]])) as api:
        yield api, connections


def frame(data: bytes) -> bytes:
    """One TCPROS message: a little-endian length, then the bytes."""
    return struct.pack("<I", len(data)) + data


def wait_for(condition: Callable[[], object], timeout: float = 10.0) -> None:
    """Wait (a hang guard, not a measurement) until ``condition()`` holds."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)
