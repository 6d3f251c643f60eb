"""``predict --live`` / ``--rerun-serve`` end within seconds after the last frame whatever their clients do (one that
never reads, many half-open ones), with ``frames.json`` complete; they listen on 127.0.0.1 unless told otherwise."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from tests.robotics._faulty_bag import IMAGE_TOPIC, POINTS_TOPIC
from tests.robotics.test_long_runs import write_bag

pytest.importorskip("rosbags")

TOPICS = ["--image-topic", IMAGE_TOPIC, "--points-topic", POINTS_TOPIC]
#: Frames of a paced run (0.1 s apart): long enough for the clients to connect while it runs.
N_FRAMES = 8


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(tmp_path: Path, *args: str) -> tuple[threading.Thread, dict[str, Any], Path]:
    """``predict`` on a paced bag in a daemon thread (``--realtime``: about 0.8 s), its result in the dict."""
    bag, out = write_bag(tmp_path / "b_mcap", N_FRAMES, 32, 48), tmp_path / "out"
    result: dict[str, Any] = {}
    cmd = ["predict", "--bag", str(bag), *TOPICS, "--method", "classical", "--out", str(out), "--realtime", *args]
    thread = threading.Thread(target=lambda: result.update(res=CliRunner().invoke(main, cmd)), daemon=True)
    thread.start()
    return thread, result, out


def _connect(port: int) -> socket.socket:
    deadline = time.monotonic() + 20
    while True:
        try:
            return socket.create_connection(("127.0.0.1", port), timeout=5)
        except OSError:
            assert time.monotonic() < deadline, f"nothing listens on {port}"
            time.sleep(0.01)


def _ends_complete(thread: threading.Thread, result: dict[str, Any], out: Path) -> str:
    """The run ended within seconds, exit 0, with frames.json complete; its output."""
    thread.join(20)
    assert not thread.is_alive(), "the run did not end after its last frame"
    res = result["res"]
    assert res.exit_code in (0, 4), res.output  # 4: --realtime dropped a frame on a busy machine
    doc = json.loads((out / "frames.json").read_text())
    assert doc["complete"] is True and doc["counts"]["pending"] == 0
    return str(res.output)


def _listening(port: int) -> set[str]:
    """The addresses this process listens on at ``port`` (from /proc/net/tcp*, hex little-endian IPv4)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            ip, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:  # LISTEN
                found.add(socket.inet_ntoa(bytes.fromhex(ip)[::-1]) if len(ip) == 8 else ip)
    return found


def test_live_ends_with_a_client_that_never_reads(tmp_path: Path) -> None:
    pytest.importorskip("foxglove")
    ws_client = pytest.importorskip("websockets.sync.client")
    from tests.robotics.test_live import SUBPROTOCOLS, TOPICS_ALL, _handshake

    port = _free_port()
    thread, result, out = _start(tmp_path, "--live", f"127.0.0.1:{port}")
    _connect(port).close()  # the server is up
    connect = {"subprotocols": SUBPROTOCOLS, "open_timeout": 5, "close_timeout": 0.2, "max_queue": 1}
    with ws_client.connect(f"ws://127.0.0.1:{port}", **connect) as ws:
        _handshake(ws, TOPICS_ALL)  # subscribed to every channel; from here on it reads nothing
        half_open = [_connect(port) for _ in range(60)]  # past the cap: the later ones are closed at once
        try:
            _ends_complete(thread, result, out)
        finally:
            for s in half_open:
                s.close()


def test_rerun_serve_listens_on_loopback_and_ends_with_a_silent_client(tmp_path: Path) -> None:
    pytest.importorskip("rerun")
    port = _free_port()
    thread, result, out = _start(tmp_path, "--rerun-serve", f"127.0.0.1:{port}")
    clients = [_connect(port) for _ in range(20)]
    clients[0].sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes(9))  # an HTTP/2 client that never reads
    try:
        assert _listening(port) == {"127.0.0.1"}
        output = _ends_complete(thread, result, out)
    finally:
        for s in clients:
            s.close()
    assert f"rerun+http://127.0.0.1:{port}/proxy" in output and "warning" not in output


@pytest.mark.parametrize("option", ["--live", "--rerun-serve"])
def test_a_bad_address_is_one_line(tmp_path: Path, option: str) -> None:
    for bad in ("127.0.0.1:\u00b2", "127.0.0.1:70000", "host:", ":1"):
        res = CliRunner().invoke(
            main, ["predict", "--bag", str(tmp_path), *TOPICS, "--out", str(tmp_path / "o"), option, bad]
        )
        assert res.exit_code == 2 and "expected [HOST:]PORT" in res.output, res.output
        assert not isinstance(res.exception, ValueError)
