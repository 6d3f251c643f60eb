"""A TCP front for a local server that no client can hold: a connection cap, a handshake timeout, a bounded close.

The live servers (``--live``: :mod:`~semattnet.robotics.live`; ``--rerun-serve``: :mod:`~semattnet.robotics.rerun`)
run in libraries that may wait for every connection when they stop (foxglove-sdk waits on a half-open one).
:class:`Gate` listens on the user's address instead and relays each client to the server on a private
loopback port, but only after the client's first request (an HTTP upgrade, a gRPC-web request or the HTTP/2
preface) came in full, within :data:`HANDSHAKE_S`; at most :data:`MAX_CLIENTS` clients at once. A connection
beyond the cap takes the place of the oldest one still waiting for its first request (which is closed), so idle or
half-open connections, however many, never lock a real client out; only when every client is relayed is a new
one closed at once. A client that stops reading holds at most a socket buffer here: the relay stops reading
from the server, whose own per-client queue then drops its oldest messages (foxglove-sdk keeps
:data:`~semattnet.robotics.live.CLIENT_BACKLOG`), and after :data:`STALL_S` without taking a byte (a peer gone
without a word: a half-open connection) it is dropped, its place freed. :meth:`Gate.close` drops every client at
once.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import threading

from semattnet._errors import InputError

__all__ = ["HANDSHAKE_S", "MAX_CLIENTS", "STALL_S", "Gate", "exposed", "is_loopback", "parse_address"]

#: Seconds a client has to send its first request in full before it is closed.
HANDSHAKE_S = 5.0
#: Clients served at once; a connection beyond it is closed at once.
MAX_CLIENTS = 32
#: The largest first request (an HTTP upgrade is well under 1 KiB).
MAX_REQUEST = 16 * 1024
#: Connections the system queues before the gate takes them.
BACKLOG = 512
#: Seconds a relayed client may leave the bytes sent to it unread (a peer gone without a word, a client that stopped
#: reading) before it is dropped: its place is not held for ever.
STALL_S = 30.0
#: Seconds :meth:`Gate.close` (and :meth:`Gate.start`) wait at most.
CLOSE_S = 2.0


def parse_address(address: str, what: str = "address") -> tuple[str, int]:
    """``"[HOST:]PORT"`` -> (host, port); host defaults to 127.0.0.1, ``[::1]:PORT`` for IPv6; port 0 = any free.
    A malformed address: one-line :class:`InputError` starting with ``what`` (e.g. ``live address``)."""
    text = str(address).strip()
    host, sep, port = text.rpartition(":")
    host = host.strip("[]") if sep else "127.0.0.1"
    if not (port.isascii() and port.isdigit()) or int(port) > 65535 or (sep and not host):
        raise InputError(f"{what} {address!r}: expected [HOST:]PORT with PORT 0-65535 (e.g. 127.0.0.1:8765)")
    return host, int(port)


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this machine only (127.0.0.0/8, ::1, ``localhost``)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def exposed(option: str, host: str, url: str) -> str:
    """The one-line warning of a server bound to ``host``, not this machine only."""
    return f"warning: {option} serves {url} to other machines ({host} is not loopback): anyone who reaches it can watch"


class Gate:
    """Listen on ``host:port`` and relay each client to ``upstream`` (module doc).

    Args:
        host: the address to listen on.
        port: the port to listen on (0: a free port, see :attr:`port`).
        upstream: the (host, port) of the server the clients are relayed to.
        max_clients: clients at once (:data:`MAX_CLIENTS`).
        handshake_s: seconds for a client's first request (:data:`HANDSHAKE_S`).
        stall_s: seconds a relayed client may leave what is sent to it unread (:data:`STALL_S`).
    """

    def __init__(
        self,
        host: str,
        port: int,
        upstream: tuple[str, int],
        *,
        max_clients: int = MAX_CLIENTS,
        handshake_s: float = HANDSHAKE_S,
        stall_s: float = STALL_S,
    ) -> None:
        self.host, self.upstream = host, upstream
        self.max_clients, self.handshake_s, self.stall_s = max_clients, handshake_s, stall_s
        self.port = port
        self.refused = 0  #: connections closed because :attr:`max_clients` were being relayed
        self.evicted = 0  #: connections still without their first request closed to make room for a newer one
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="semattnet-gate", daemon=True)
        self._server: asyncio.Server | None = None
        self._clients: set[asyncio.Task[None]] = set()
        self._waiting: dict[asyncio.Task[None], None] = {}  # clients without their first request, oldest first

    def start(self) -> int:
        """Start listening; returns the port. Raises :class:`OSError` when the address cannot be served."""
        self._thread.start()
        start = asyncio.start_server(self._serve, self.host, self.port, limit=MAX_REQUEST, backlog=BACKLOG)
        try:
            self._server = asyncio.run_coroutine_threadsafe(start, self._loop).result(CLOSE_S)
        except BaseException:
            self._stop_loop()
            raise
        self.port = int(self._server.sockets[0].getsockname()[1])
        return self.port

    @property
    def clients(self) -> int:
        """Clients connected now (their first request under way or relayed)."""
        return len(self._clients)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is None or not self._make_room():
            self.refused += 1
            writer.transport.abort()
            return
        self._clients.add(task)
        self._waiting[task] = None
        try:
            await self._relay(reader, writer)
        except (
            OSError,
            asyncio.TimeoutError,
            asyncio.IncompleteReadError,
            asyncio.LimitOverrunError,
            asyncio.CancelledError,
        ):
            pass  # a client that went away, never finished its request or sent too much, or close(): closed below
        finally:
            self._clients.discard(task)
            self._waiting.pop(task, None)
            writer.transport.abort()

    def _make_room(self) -> bool:
        """Whether a new client fits: under the cap, or in the place of the oldest client still waiting for its
        first request (closed now)."""
        if len(self._clients) < self.max_clients:
            return True
        oldest = next(iter(self._waiting), None)
        if oldest is None:
            return False
        del self._waiting[oldest]
        self._clients.discard(oldest)
        oldest.cancel()
        self.evicted += 1
        return True

    async def _relay(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """The client's first request within the handshake time, then both directions until either side ends."""
        request = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), self.handshake_s)
        task = asyncio.current_task()
        if task is not None:
            self._waiting.pop(task, None)  # relayed from now on: not to be evicted
        up_reader, up_writer = await asyncio.wait_for(asyncio.open_connection(*self.upstream), self.handshake_s)
        try:
            up_writer.write(request)
            pumps = [
                asyncio.ensure_future(_pump(reader, up_writer, None)),
                asyncio.ensure_future(_pump(up_reader, writer, self.stall_s)),
            ]
            try:
                await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for p in pumps:
                    p.cancel()
                await asyncio.gather(*pumps, return_exceptions=True)
        finally:
            up_writer.transport.abort()

    def close(self) -> None:
        """Stop listening and drop every client; returns within about :data:`CLOSE_S` whatever the clients do."""
        if self._thread.is_alive():
            with contextlib.suppress(Exception):  # a loop that will not answer is stopped below all the same
                asyncio.run_coroutine_threadsafe(self._drop_all(), self._loop).result(CLOSE_S)
        self._stop_loop()

    async def _drop_all(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._clients):
            task.cancel()
        await asyncio.wait_for(asyncio.gather(*self._clients, return_exceptions=True), CLOSE_S / 2)

    def _stop_loop(self) -> None:
        if self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(CLOSE_S)
        if not self._thread.is_alive() and not self._loop.is_closed():
            self._loop.close()


async def _pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter, stall_s: float | None) -> None:
    """Bytes from ``src`` to ``dst`` until ``src`` ends; waits while ``dst`` is full (so ``src`` is not read), at
    most ``stall_s`` seconds at a time (then it ends: the client is dropped)."""
    while data := await src.read(64 * 1024):
        dst.write(data)
        await asyncio.wait_for(dst.drain(), stall_s)
