"""A hostile ROS 1 publisher or master is one line, never a traceback: garbage XML, an HTTP error page, an HTML
page, a URI without a port or not http, a port out of range, a garbage TCPROS header. Each is one warning naming
the topic (the node goes on: it still receives from a good publisher) or, from the master at start, one error
line; no thread ends in a traceback (``threading.excepthook`` is watched, and stderr)."""

from __future__ import annotations

import logging
import socket
import threading
import time
import xmlrpc.client
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from semattnet.robotics.ros.tcpros import TcprosError, TcprosTransport
from semattnet.robotics.ros.transport import SENSOR_QOS

from ._hostile_ros1 import frame, raw_http, tcpros_publisher, threaded_master, wait_for, xmlrpc_reply

pytest.importorskip("rosbags")
from semattnet.robotics.bags.encode import depth_image_message

IMAGE = "sensor_msgs/msg/Image"
LOGGER = "semattnet.robotics.ros.tcpros"
HTML = b"<html><head><title>502 Bad Gateway</title></head><body>\n<h1>Bad Gateway</h1>\n</body></html>\n"
GARBAGE_XML = b"<?xml version='1.0'?><methodResponse><params><param><value><int>zz</int></value>"
FAULT = xmlrpc.client.dumps(xmlrpc.client.Fault(1, "no\nforged line"), methodresponse=True).encode()
REPLIES = {
    "garbage XML": b"HTTP/1.0 200 OK\r\nContent-Length: %d\r\n\r\n" % len(GARBAGE_XML) + GARBAGE_XML,
    "an HTTP error page": b"HTTP/1.0 502 Bad Gateway\r\nContent-Type: text/html\r\n\r\n" + HTML,
    "an HTML page": b"HTTP/1.0 200 OK\r\nContent-Type: text/html\r\n\r\n" + HTML,
    "not HTTP": b"SSH-2.0-OpenSSH_9.2\r\n",
    "a fault": b"HTTP/1.0 200 OK\r\nContent-Length: %d\r\n\r\n" % len(FAULT) + FAULT,
    "a port out of range": xmlrpc_reply([1, "", ["TCPROS", "127.0.0.1", 70000]]),
    "a host that is no name": xmlrpc_reply([1, "", ["TCPROS", "a\x00b", 1234]]),
    "a value of the wrong shape": xmlrpc_reply([1, "", "TCPROS"]),
}


@pytest.fixture
def watched(monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> Iterator[list[Any]]:
    """What reached ``threading.excepthook`` (a thread's traceback); at the end, nothing did and stderr holds no
    traceback."""
    hooked: list[Any] = []
    monkeypatch.setattr(threading, "excepthook", hooked.append)
    yield hooked
    assert not hooked, [(h.exc_type, h.exc_value) for h in hooked]
    assert "Traceback" not in capfd.readouterr().err


def _good_frame(transport: TcprosTransport) -> bytes:
    message = depth_image_message(transport.typestore, np.ones((3, 4), np.float32), 1, "camera")
    return frame(bytes(transport.typestore.serialize_ros1(message, IMAGE)))


def _one_line_then_a_good_publisher(
    uri: str, caplog: pytest.LogCaptureFixture, transport: TcprosTransport, master: Any
) -> str:
    """Subscribe /depth with ``uri`` listed as its publisher: the one warning about it; then a good publisher
    listed beside it still delivers."""
    received: list[object] = []
    caplog.set_level(logging.WARNING, LOGGER)
    master.publishers["/depth"] = [uri]
    transport.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    wait_for(lambda: [r for r in caplog.records if "/depth" in r.getMessage()])
    md5 = transport.typestore.generate_msgdef(IMAGE)[1]
    good = _good_frame(transport)
    with tcpros_publisher(md5, lambda conn, n: (conn.sendall(good), time.sleep(1.0))) as (api, _):
        xmlrpc.client.ServerProxy(transport.uri).publisherUpdate("/master", "/depth", [uri, api])
        wait_for(lambda: received)
    lines = [r.getMessage() for r in caplog.records if "/depth" in r.getMessage()]
    assert len(lines) == 1 and "\n" not in lines[0], lines
    return lines[0]


@pytest.mark.parametrize("what", sorted(REPLIES))
def test_a_publishers_hostile_xmlrpc_reply_is_one_line(
    what: str, watched: list[Any], caplog: pytest.LogCaptureFixture
) -> None:
    with (
        threaded_master() as master,
        TcprosTransport(master.uri, "/listener", "127.0.0.1", timeout=1.0) as listener,
        raw_http(REPLIES[what]) as uri,
    ):
        line = _one_line_then_a_good_publisher(uri, caplog, listener, master)
    assert line.startswith("/depth: publisher") and "dropped" in line, line


@pytest.mark.parametrize("uri", ["http://127.0.0.1/", "ftp://127.0.0.1:21/", "http://:11311/", "127.0.0.1:1234"])
def test_a_publisher_uri_without_a_port_or_not_http_is_one_line(
    uri: str, watched: list[Any], caplog: pytest.LogCaptureFixture
) -> None:
    with threaded_master() as master, TcprosTransport(master.uri, "/listener", "127.0.0.1", timeout=1.0) as listener:
        line = _one_line_then_a_good_publisher(uri, caplog, listener, master)
    assert "http://host:port" in line, line


@pytest.mark.parametrize(
    "header",
    [b"\x08\x00\x00\x00garbage!", b"\x04\x00\x00\x00\xff\xff\xff\x7f", b"\x06\x00\x00\x00\x02\x00\x00\x00\xff="],
    ids=["a field without '='", "a field longer than the header", "a field not UTF-8"],
)
def test_a_publishers_garbage_tcpros_header_is_one_line(
    header: bytes, watched: list[Any], caplog: pytest.LogCaptureFixture
) -> None:
    with threaded_master() as master, TcprosTransport(master.uri, "/listener", "127.0.0.1", timeout=1.0) as listener:
        md5 = listener.typestore.generate_msgdef(IMAGE)[1]
        with tcpros_publisher(md5, lambda conn, n: time.sleep(1.0), header=header) as (api, _):
            line = _one_line_then_a_good_publisher(api, caplog, listener, master)
    assert "connection header" in line, line


@pytest.mark.parametrize("what", ["garbage XML", "an HTTP error page", "an HTML page", "not HTTP", "a fault"])
def test_a_hostile_master_at_start_is_one_line(what: str, watched: list[Any]) -> None:
    with raw_http(REPLIES[what]) as uri, pytest.raises(TcprosError) as info:
        TcprosTransport(uri, "/node", "127.0.0.1", timeout=1.0)
    message = str(info.value)
    assert message.startswith(f"ROS master {uri} getUri: ") and "\n" not in message, message


def test_a_garbage_registration_reply_is_one_line(watched: list[Any]) -> None:
    with threaded_master() as master:
        master.canned["registerSubscriber"] = REPLIES["garbage XML"]
        with TcprosTransport(master.uri, "/node", "127.0.0.1", timeout=1.0) as node:
            with pytest.raises(TcprosError, match="registerSubscriber: not an XML-RPC reply"):
                node.subscribe("/depth", IMAGE, SENSOR_QOS, lambda message: None)


def test_a_client_breaking_off_mid_request_leaves_no_traceback(watched: list[Any]) -> None:
    with threaded_master() as master, TcprosTransport(master.uri, "/node", "127.0.0.1", timeout=1.0) as node:
        port = int(node.uri.rsplit(":", 1)[1].strip("/"))
        for request in (b"POST / HTTP/1.0\r\nContent-Length: 50\r\n\r\n<?xml", b"GARBAGE\r\n\r\n", b"\xff" * 100):
            with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
                sock.sendall(request)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
        assert xmlrpc.client.ServerProxy(node.uri).getPid("/x")[0] == 1
