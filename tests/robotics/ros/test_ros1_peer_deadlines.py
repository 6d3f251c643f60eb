"""Every wait of the ROS 1 transport on a peer is bounded by a deadline per call, not per read: a master or a
publisher that drips one byte at a time is given up at the call's deadline; one peer dripping into the node's
XML-RPC port holds no other caller; a publisher that stalls mid-message is dropped with one line and reconnected;
close ends within a second whatever the master does at unregister; the ``shutdown`` call stops the node."""

from __future__ import annotations

import logging
import socket
import threading
import time
import xmlrpc.client
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from semattnet.robotics.ros._ros1_xmlrpc import MAX_XMLRPC_CLIENTS
from semattnet.robotics.ros.tcpros import TcprosError, TcprosTransport
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS

from ._hostile_ros1 import ThreadedMaster, drip, frame, tcpros_publisher, threaded_master, wait_for

pytest.importorskip("rosbags")
from semattnet.robotics.bags.encode import depth_image_message

IMAGE = "sensor_msgs/msg/Image"
LOGGER = "semattnet.robotics.ros.tcpros"
#: A hang guard for calls that, unbounded, would wait for ever (not a measurement).
GUARD_S = 30.0


def _within(call: Callable[[], object], guard: float = GUARD_S) -> tuple[float, object]:
    """``call()`` in a thread: the seconds it took and what it returned or raised (a hang fails the test)."""
    result: list[object] = []

    def run() -> None:
        try:
            result.append(call())
        except BaseException as exc:
            result.append(exc)

    start = time.monotonic()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(guard)
    assert not thread.is_alive(), f"still waiting after {guard} s"
    return time.monotonic() - start, result[0]


@pytest.fixture
def master() -> Iterator[ThreadedMaster]:
    with threaded_master(frozenset({"unregisterPublisher", "unregisterSubscriber"}), period=0.3) as fake:
        yield fake


def test_a_master_dripping_its_reply_is_given_up_at_the_call_deadline() -> None:
    """A byte every 0.3 s never trips a 1 s read timeout; the call's 1 s deadline ends it, in one line."""
    with threaded_master(frozenset({"getUri"}), period=0.3) as dripping:
        took, result = _within(lambda: TcprosTransport(dripping.uri, "/n", "127.0.0.1", timeout=1.0))
    assert isinstance(result, TcprosError), result
    assert "getUri" in str(result) and "no whole reply within 1 s" in str(result) and "\n" not in str(result)
    assert took < 5.0, took  # the deadline (1 s) and a margin; unbounded it would drip for 8 hours


def test_a_peer_dripping_into_the_xmlrpc_port_holds_no_other_caller(master: ThreadedMaster) -> None:
    with TcprosTransport(master.uri, "/talker", "127.0.0.1", timeout=2.0) as talker:
        port = int(talker.uri.rsplit(":", 1)[1].strip("/"))
        stop = threading.Event()
        slow = socket.create_connection(("127.0.0.1", port), timeout=GUARD_S)
        request = b"POST / HTTP/1.0\r\nContent-Length: 200\r\n\r\n" + b" " * 200
        dripper = threading.Thread(target=drip, args=(slow, request, 0.3, stop), daemon=True)
        dripper.start()
        try:
            proxy = xmlrpc.client.ServerProxy(talker.uri)
            _, pid = _within(lambda: proxy.getPid("/other"))
            assert isinstance(pid, list) and pid[0] == 1, pid  # answered while the dripper holds its connection
            _, gone = _within(lambda: slow.recv(100))  # dropped at the request's deadline (2 s), unanswered
            assert gone == b"" or isinstance(gone, ConnectionResetError), gone
        finally:
            stop.set()
            slow.close()
            dripper.join(5)


def test_the_xmlrpc_port_bounds_its_connections(master: ThreadedMaster) -> None:
    """32 silent connections at once at most: the 8 beyond are closed unanswered at once (not queued behind the
    silent ones), and once the silent ones reach their deadline (2 s) callers are answered again."""
    with TcprosTransport(master.uri, "/talker", "127.0.0.1", timeout=2.0) as talker:
        port = int(talker.uri.rsplit(":", 1)[1].strip("/"))
        idle = [socket.create_connection(("127.0.0.1", port), timeout=GUARD_S) for _ in range(MAX_XMLRPC_CLIENTS + 8)]
        try:
            time.sleep(0.5)
            assert sum(_closed(sock) for sock in idle) >= 8  # beyond the bound: closed at once
            wait_for(lambda: _answers(talker.uri))  # and once the idle ones reach their deadline, callers again
        finally:
            for sock in idle:
                sock.close()


def _closed(sock: socket.socket) -> bool:
    """Whether the server closed ``sock`` (without waiting for it to)."""
    sock.settimeout(0.01)
    try:
        return sock.recv(1) == b""
    except TimeoutError:
        return False
    except ConnectionResetError:
        return True


def _answers(uri: str) -> bool:
    try:
        return xmlrpc.client.ServerProxy(uri).getPid("/x")[0] == 1
    except OSError:
        return False


def test_a_publisher_stalling_mid_message_is_dropped_and_reconnected(
    master: ThreadedMaster, caplog: pytest.LogCaptureFixture
) -> None:
    received: list[object] = []
    with TcprosTransport(master.uri, "/listener", "127.0.0.1", timeout=1.0) as listener:
        md5 = listener.typestore.generate_msgdef(IMAGE)[1]
        message = depth_image_message(listener.typestore, np.ones((3, 4), np.float32), 1, "camera")
        good = bytes(listener.typestore.serialize_ros1(message, IMAGE))

        def then(conn: socket.socket, n: int) -> None:
            if n == 0:  # the first connection: half a message, then nothing (alive, silent)
                conn.sendall(frame(good)[: len(good) // 2])
                time.sleep(GUARD_S)
            else:
                conn.sendall(frame(good))
                time.sleep(1.0)

        caplog.set_level(logging.WARNING, LOGGER)
        with tcpros_publisher(md5, then) as (api, connections):
            master.publishers["/depth"] = [api]
            listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
            wait_for(lambda: received)
    assert len(connections) >= 2  # reconnected through requestTopic
    lines = [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]
    assert len(lines) == 1 and "/depth" in lines[0] and "stalled" in lines[0], lines


def test_a_publisher_dripping_its_header_is_given_up_at_the_deadline(
    master: ThreadedMaster, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, LOGGER)
    with TcprosTransport(master.uri, "/listener", "127.0.0.1", timeout=1.0) as listener:
        md5 = listener.typestore.generate_msgdef(IMAGE)[1]
        stop = threading.Event()
        long_header = b"\xff\x00\x00\x00" + b"x" * 255
        with tcpros_publisher(md5, lambda conn, n: drip(conn, long_header, 0.3, stop), header=b"") as (api, _):
            master.publishers["/depth"] = [api]
            listener.subscribe("/depth", IMAGE, SENSOR_QOS, lambda message: None)
            wait_for(lambda: any("dropped" in r.getMessage() for r in caplog.records))
            stop.set()
    line = next(r.getMessage() for r in caplog.records if "dropped" in r.getMessage())
    assert "stalled" in line and "\n" not in line, line


def test_close_ends_within_a_second_whatever_the_master_does_at_unregister(
    master: ThreadedMaster, caplog: pytest.LogCaptureFixture
) -> None:
    transport = TcprosTransport(master.uri, "/node", "127.0.0.1", timeout=5.0)
    for k in range(4):
        transport.advertise(f"/out{k}", IMAGE, OUTPUT_QOS)
        transport.subscribe(f"/in{k}", IMAGE, SENSOR_QOS, lambda message: None)
    caplog.set_level(logging.WARNING, LOGGER)
    took, _ = _within(transport.close)
    assert master.dripped  # the master dripped at unregister
    assert took < 1.5, took  # 0.5 s for the master in all, the threads' poll period: not 8 x 2 s
    lines = [r.getMessage() for r in caplog.records if "unregister" in r.getMessage()]
    assert len(lines) == 1 and "topic(s) left registered" in lines[0], lines


def test_the_shutdown_call_is_one_line_naming_the_caller_and_its_reason(
    master: ThreadedMaster, caplog: pytest.LogCaptureFixture
) -> None:
    told = threading.Event()
    caplog.set_level(logging.WARNING, LOGGER)
    transport = TcprosTransport(master.uri, "/node", "127.0.0.1", timeout=2.0, on_shutdown=told.set)
    transport.advertise("/depth", IMAGE, OUTPUT_QOS)
    reply = xmlrpc.client.ServerProxy(transport.uri).shutdown("/master", "new node registered with same name")
    assert reply[0] == 1 and told.is_set()
    _within(transport.close)
    [line] = [r.getMessage() for r in caplog.records if "shut down" in r.getMessage()]
    assert "'/master'" in line and "new node registered with same name" in line, line
