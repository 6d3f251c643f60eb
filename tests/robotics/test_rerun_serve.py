"""RerunLogger(serve=True): the gRPC stream and the bundled web viewer on local ports, with or without a file."""

from __future__ import annotations

import socket
import time
import urllib.request
from pathlib import Path
from urllib.parse import parse_qs, urlparse

import numpy as np
import pytest

from semattnet._errors import InputError

pytest.importorskip("rerun")

K = np.array([[30.0, 0, 11.5], [0, 30.0, 7.5], [0, 0, 1]])
STAMPS = [1_317_000_000_123_456_789, 1_317_000_000_223_456_789]


def _refused(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


def _log_frames(log: object) -> None:
    for t in STAMPS:
        log.log_frame(
            t,
            np.zeros((16, 24, 3), np.uint8),
            K,
            np.eye(4),  # type: ignore[attr-defined]
            depth=np.full((16, 24), 5.0, np.float32),
        )


def test_serve_web_viewer_and_grpc(tmp_path: Path) -> None:
    """The viewer page answers 200 HTML (served from the wheel) with the stream's URL; the file is still written;
    the gRPC port closes with the logger."""
    from semattnet.robotics.rerun import ENTITIES, RerunLogger, read_rrd_frames

    log = RerunLogger(tmp_path / "run.rrd", serve=True, grpc_port=0, web_port=0)
    assert log.url is not None and log.grpc_url is not None
    grpc = urlparse(log.grpc_url)
    assert (grpc.scheme, grpc.hostname, grpc.path) == ("rerun+http", "127.0.0.1", "/proxy")
    web = urlparse(log.url)
    assert parse_qs(web.query)["url"] == [log.grpc_url]
    _log_frames(log)
    assert not _refused(int(grpc.port or 0))
    with urllib.request.urlopen(log.url, timeout=10) as r:
        assert r.status == 200 and r.headers["content-type"].startswith("text/html")
        assert b"<html" in r.read().lower()
    log.close()
    assert read_rrd_frames(tmp_path / "run.rrd")[ENTITIES["depth"]] == STAMPS
    deadline = time.monotonic() + 5
    while not _refused(int(grpc.port or 0)):
        assert time.monotonic() < deadline, "the gRPC server still listens after close()"
        time.sleep(0.02)


def test_serve_port_in_use_is_one_line() -> None:
    """A gRPC or web port in use: one-line InputError naming it (rerun itself would only log it)."""
    from semattnet.robotics.rerun import RerunLogger

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        for kw in ({"grpc_port": port, "web_port": 0}, {"grpc_port": 0, "web_port": port}):
            with pytest.raises(InputError, match=f"cannot serve .* on .*:{port} ") as e:
                RerunLogger(serve=True, **kw)  # type: ignore[arg-type]
            assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="serve=True"):
        RerunLogger()


def _read_messages(port: int) -> bytes:
    """The start of the recording as a viewer reads it (gRPC-web ``ReadMessages`` over HTTP/1.1)."""
    req = urllib.request.Request(
        f"http://127.0.0.1:{port}/rerun.sdk_comms.v1alpha1.MessageProxyService/ReadMessages",
        data=bytes(5),
        method="POST",
        headers={"content-type": "application/grpc-web+proto", "x-grpc-web": "1"},
    )
    with urllib.request.urlopen(req, timeout=5) as r:
        assert r.status == 200 and r.headers["content-type"] == "application/grpc-web+proto"
        return bytes(r.read(4096))


def test_viewers_reach_the_stream_through_the_gate() -> None:
    """The stream is read through the gate (the app id in the recording's first messages); connections beyond the
    gate's cap make room by closing the oldest ones without a request; a viewer that stops reading and 60 half-open
    ones do not hold close()."""
    from semattnet.robotics.gate import MAX_CLIENTS
    from semattnet.robotics.rerun import RerunLogger

    log = RerunLogger(serve=True, grpc_port=0, app_id="gate_check")
    port = int(urlparse(log.grpc_url or "").port or 0)
    _log_frames(log)
    assert b"gate_check" in _read_messages(port)
    silent = socket.create_connection(("127.0.0.1", port), timeout=5)
    silent.sendall(
        b"POST /rerun.sdk_comms.v1alpha1.MessageProxyService/ReadMessages HTTP/1.1\r\nHost: x\r\n"
        b"content-type: application/grpc-web+proto\r\ncontent-length: 5\r\n\r\n" + bytes(5)
    )
    assert silent.recv(1)  # its request read and relayed (else it could be the oldest without one), then no more
    held = [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(60)]
    try:
        # past the cap, each new one takes the place of the oldest one without a request (the silent one keeps its)
        closed = sum(s.recv(1) == b"" for s in held[: 60 - (MAX_CLIENTS - 1)])
        assert closed == 60 - (MAX_CLIENTS - 1)
        _log_frames(log)
        start = time.monotonic()
        log.close()
        assert time.monotonic() - start < 5
    finally:
        for s in [silent, *held]:
            s.close()


def test_the_file_is_complete_before_the_stream_stops(tmp_path: Path) -> None:
    """finish_file: the recording in place and whole while viewers still read the stream; close stops the stream."""
    from semattnet.robotics.rerun import ENTITIES, RerunLogger, read_rrd_frames

    log = RerunLogger(tmp_path / "run.rrd", serve=True, grpc_port=0)
    port = int(urlparse(log.grpc_url or "").port or 0)
    _log_frames(log)
    log.finish_file()
    assert read_rrd_frames(tmp_path / "run.rrd")[ENTITIES["depth"]] == STAMPS
    assert b"semattnet" in _read_messages(port)  # still served
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]
    log.close()
    deadline = time.monotonic() + 5
    while not _refused(port):
        assert time.monotonic() < deadline, "the stream still listens after close()"
        time.sleep(0.02)
