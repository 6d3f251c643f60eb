"""Fixtures for the hub tests: an HTTP server on 127.0.0.1, an empty cache, tiny models."""

from __future__ import annotations

import re
import socket
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
import torch

import semattnet
from tests._helpers import online_cache


@dataclass
class ServerState:
    """What the test server serves and what it was asked."""

    files: dict[str, bytes] = field(default_factory=dict)
    #: path -> number of bytes after which the *next* response to that path is cut off
    cut_after: dict[str, int] = field(default_factory=dict)
    honour_range: bool = True
    requests: list[tuple[str, str | None]] = field(default_factory=list)


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def do_GET(self) -> None:
        state: ServerState = self.server.state  # type: ignore[attr-defined]
        rng = self.headers.get("Range")
        state.requests.append((self.path, rng))
        body = state.files.get(self.path)
        if body is None:
            self.send_response(404)
            self.send_header("Content-Length", "0")
            self.end_headers()
            return
        start, status = 0, 200
        m = re.fullmatch(r"bytes=(\d+)-", rng or "")
        if m and state.honour_range:
            start, status = int(m.group(1)), 206
            if start >= len(body):
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{len(body)}")
                self.send_header("Content-Length", "0")
                self.end_headers()
                return
        chunk = body[start:]
        self.send_response(status)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Content-Length", str(len(chunk)))
        self.send_header("Accept-Ranges", "bytes")
        if status == 206:
            self.send_header("Content-Range", f"bytes {start}-{len(body) - 1}/{len(body)}")
        self.end_headers()
        cut = state.cut_after.pop(self.path, None)
        if cut is not None:  # send part of the body, then drop the connection
            self.wfile.write(chunk[:cut])
            self.wfile.flush()
            self.close_connection = True
            self.connection.shutdown(socket.SHUT_RDWR)
            return
        self.wfile.write(chunk)

    def log_message(self, format: str, *args: object) -> None:  # quiet
        pass


class Server:
    def __init__(self) -> None:
        self.state = ServerState()
        self._httpd = ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
        self._httpd.daemon_threads = True
        self._httpd.state = self.state  # type: ignore[attr-defined]
        self._thread = threading.Thread(target=self._httpd.serve_forever, daemon=True)
        self._thread.start()
        self.running = True

    def url(self, path: str) -> str:
        return f"http://127.0.0.1:{self._httpd.server_address[1]}{path}"

    def add(self, path: str, body: bytes) -> str:
        self.state.files[path] = body
        return self.url(path)

    def stop(self) -> None:
        if self.running:
            self._httpd.shutdown()
            self._httpd.server_close()
            self.running = False

    def gets(self, path: str) -> list[str | None]:
        """The Range header of each GET of ``path`` (None when absent)."""
        return [r for p, r in self.state.requests if p == path]


@pytest.fixture
def server() -> Iterator[Server]:
    srv = Server()
    yield srv
    srv.stop()


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty cache in $SEMATTNET_CACHE, online."""
    root = tmp_path / "cache"
    online_cache(monkeypatch, root)
    return root


def cache_files(root: Path) -> list[str]:
    """Files in the cache other than locks and pins."""
    if not root.exists():
        return []
    return sorted(
        p.relative_to(root).as_posix()
        for p in root.rglob("*")
        if p.is_file() and ".locks" not in p.parts and p.name != "pins.json"
    )


@pytest.fixture(scope="session")
def tiny_model() -> torch.nn.Module:
    """The smallest full model the registry builds (width 0.125, ~5.7 M parameters, 2 + 2 propagation steps)."""
    torch.manual_seed(1)
    model = semattnet.build_model("semattnet", width=0.125, iterations=2).eval()
    with torch.no_grad():  # non-trivial BN statistics, so that a wrong load would show in the outputs
        for m in model.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.1, 0.1)
                m.running_var.uniform_(0.5, 1.5)
    return model


@pytest.fixture(scope="session")
def tiny_inputs() -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    sparse = (torch.rand(1, 1, 32, 32, generator=g) * 60 + 1) * (torch.rand(1, 1, 32, 32, generator=g) < 0.1)
    return {
        "rgb": torch.rand(1, 3, 32, 32, generator=g) * 255,
        "semantic": torch.rand(1, 3, 32, 32, generator=g) * 255,
        "sparse": sparse,
    }


@pytest.fixture(scope="session")
def expected(tiny_model, tiny_inputs) -> torch.Tensor:
    """The tiny model's prediction on the tiny inputs."""
    return predict(tiny_model, tiny_inputs)


def predict(model: torch.nn.Module, inputs: dict[str, torch.Tensor]) -> torch.Tensor:
    with torch.no_grad():
        return model(**inputs).depth
