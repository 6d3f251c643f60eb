"""The gate in front of the live servers (``--live``, ``--rerun-serve``): idle and half-open connections, however
many, never lock a real client out (a newer connection takes the place of the oldest one still without its first
request); a new client is refused only when every place is relayed. Sockets from the test itself, no server
library needed."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator

import pytest

from semattnet.robotics.gate import MAX_CLIENTS, Gate

REQUEST = b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\r\n"
REPLY = b"HTTP/1.1 101 Switching Protocols\r\n\r\n"


@pytest.fixture
def upstream() -> Iterator[tuple[str, int]]:
    """A server that answers each connection's first request with :data:`REPLY` and keeps it open."""
    listener = socket.create_server(("127.0.0.1", 0))
    conns: list[socket.socket] = []

    def serve() -> None:
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            conns.append(conn)
            threading.Thread(target=lambda c=conn: c.recv(4096) and c.sendall(REPLY), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    yield listener.getsockname()
    listener.close()
    for c in conns:
        c.close()


@pytest.fixture
def gate(upstream: tuple[str, int]) -> Iterator[Gate]:
    g = Gate("127.0.0.1", 0, upstream)
    g.start()
    yield g
    g.close()


def _connect(port: int) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=5)


def _relayed(port: int) -> socket.socket:
    """A client whose first request went through: it reads the upstream's reply."""
    s = _connect(port)
    s.sendall(REQUEST)
    assert s.recv(len(REPLY)) == REPLY
    return s


def _wait_for(ok: object, what: str) -> None:
    deadline = time.monotonic() + 5
    while not ok():  # type: ignore[operator]
        if time.monotonic() > deadline:
            pytest.fail(f"waited 5 s for {what}")
        time.sleep(0.01)


def test_300_idle_connections_do_not_lock_a_client_out(gate: Gate) -> None:
    idle = [_connect(gate.port) for _ in range(300)]
    try:
        _wait_for(lambda: gate.evicted + gate.clients >= 300, "the gate to take the idle connections")
        client = _relayed(gate.port)
        client.close()
        assert gate.refused == 0 and gate.clients <= MAX_CLIENTS
        assert sum(s.recv(1) == b"" for s in idle[:200]) == 200  # the oldest ones made room
    finally:
        for s in idle:
            s.close()


def test_60_half_open_handshakes_do_not_lock_a_client_out(gate: Gate) -> None:
    half = [_connect(gate.port) for _ in range(60)]
    try:
        for s in half:
            s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n")  # never the blank line that ends the request
        _wait_for(lambda: gate.evicted + gate.clients >= 60, "the gate to take the half-open connections")
        client = _relayed(gate.port)
        client.close()
        assert gate.refused == 0
    finally:
        for s in half:
            s.close()


def test_a_new_client_is_refused_only_when_every_place_is_relayed(upstream: tuple[str, int]) -> None:
    g = Gate("127.0.0.1", 0, upstream, max_clients=3)
    port = g.start()
    held = [_relayed(port) for _ in range(3)]
    try:
        with _connect(port) as extra:
            assert extra.recv(1) == b""  # closed at once: no place waits for its first request
        assert g.refused == 1 and g.evicted == 0 and g.clients == 3
        g.close()
        assert all(s.recv(1) == b"" for s in held)  # dropped by close
    finally:
        for s in held:
            s.close()
        g.close()


def test_a_relayed_client_that_takes_nothing_is_dropped_after_the_stall_time() -> None:
    """A viewer gone without a word (half-open after its handshake) or that stopped reading frees its place."""
    listener = socket.create_server(("127.0.0.1", 0))

    def flood() -> None:  # a server that answers, then streams without end
        conn, _ = listener.accept()
        conn.recv(4096)
        try:
            while True:
                conn.sendall(b"\0" * 65536)
        except OSError:
            conn.close()

    threading.Thread(target=flood, daemon=True).start()
    g = Gate("127.0.0.1", 0, listener.getsockname(), max_clients=1, stall_s=0.3)
    port = g.start()
    try:
        with _connect(port) as silent:
            silent.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            silent.sendall(REQUEST)  # relayed, then never reads
            _wait_for(lambda: g.clients == 1, "the client to be relayed")
            _wait_for(lambda: g.clients == 0, "the stalled client to be dropped")
            assert g.refused == 0
    finally:
        g.close()
        listener.close()
