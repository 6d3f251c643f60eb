"""The ROS 1 transport in-process: our publisher to our subscriber through a fake master, and peers that misbehave."""

from __future__ import annotations

import logging
import re
import socket
import struct
import threading
import time
import xmlrpc.client
from collections.abc import Callable, Iterator
from typing import Any
from xmlrpc.server import SimpleXMLRPCServer

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semattnet._errors import InputError
from semattnet.geometry.cameras import CameraInfoData
from semattnet.robotics.ros.tcpros import MAX_PEERS, TcprosError, TcprosTransport, adopt_message, ros1_type_name
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS, TF_STATIC_QOS, QoS

from ._ros1_master import FakeMaster

rosbags = pytest.importorskip("rosbags")
from semattnet.robotics.bags.deps import rosbags_typestore  # noqa: E402
from semattnet.robotics.bags.encode import camera_info_message, depth_image_message  # noqa: E402
from semattnet.robotics.ros._tcpros_wire import decode_header, encode_header  # noqa: E402

IMAGE = "sensor_msgs/msg/Image"
STAMP = 1_700_000_000_123_456_789
DEPTH = np.arange(12, dtype=np.float32).reshape(3, 4) + 0.5
LOGGER = "semattnet.robotics.ros.tcpros"


@pytest.fixture
def master() -> Iterator[FakeMaster]:
    fake = FakeMaster()
    yield fake
    fake.close()


@pytest.fixture
def node(master: FakeMaster) -> Iterator[Callable[[str], TcprosTransport]]:
    """A factory of transports on the fake master, all closed at the end."""
    made: list[TcprosTransport] = []

    def make(name: str) -> TcprosTransport:
        made.append(TcprosTransport(master.uri, name, "127.0.0.1", timeout=2.0))
        return made[-1]

    yield make
    for transport in made:
        transport.close()


def _wait(condition: Callable[[], object], timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def _depth_message(transport: TcprosTransport) -> Any:
    return depth_image_message(transport.typestore, DEPTH, STAMP, "camera_optical")


def _publish_until(publisher: Any, message: Any, received: list[Any], count: int = 1) -> None:
    """Publish (a connection may still be handshaking) until ``count`` messages arrived."""
    deadline = time.monotonic() + 5.0
    while len(received) < count:
        assert time.monotonic() < deadline, "no message arrived"
        publisher.publish(message)
        time.sleep(0.02)


def _check_depth(message: Any) -> None:
    assert message.header.frame_id == "camera_optical"
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == divmod(STAMP, 1_000_000_000)
    assert (message.height, message.width, message.encoding, message.step) == (3, 4, "32FC1", 16)
    np.testing.assert_array_equal(np.frombuffer(message.data.tobytes(), "<f4").reshape(3, 4), DEPTH)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_any_header_bytes_are_fields_or_one_error(block: bytes) -> None:
    try:
        fields = decode_header(block)
    except TcprosError:
        return
    assert all(isinstance(k, str) and isinstance(v, str) for k, v in fields.items())


def test_type_names_and_headers() -> None:
    assert ros1_type_name(IMAGE) == "sensor_msgs/Image"
    assert ros1_type_name("sensor_msgs/Image") == "sensor_msgs/Image"
    fields = {"topic": "/a", "md5sum": "*", "message_definition": "x=y\nz"}
    block = encode_header(fields)
    assert struct.unpack("<I", block[:4])[0] == len(block) - 4
    assert decode_header(block[4:]) == fields
    with pytest.raises(TcprosError, match="truncated"):
        decode_header(block[4:-1])
    with pytest.raises(TcprosError, match="without '='"):
        decode_header(struct.pack("<I", 3) + b"abc")


@pytest.mark.parametrize("subscribe_first", [False, True], ids=["publisher-first", "publisherUpdate"])
def test_publisher_to_subscriber(node: Callable[[str], TcprosTransport], subscribe_first: bool) -> None:
    """Both orders: the subscriber finds the publisher at registration, or is told by publisherUpdate."""
    talker, listener = node("/talker"), node("/listener")
    received: list[Any] = []
    if subscribe_first:
        listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    publisher = talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    if not subscribe_first:
        listener.subscribe("/depth", "sensor_msgs/Image", SENSOR_QOS, received.append)
    _publish_until(publisher, _depth_message(talker), received)
    _check_depth(received[0])
    assert publisher.subscriber_count == 1


def test_get_bus_info_lists_the_connections_as_rospy_does(node: Callable[[str], TcprosTransport]) -> None:
    """``rosnode info`` reads getBusInfo: [id, destination, direction, transport, topic, connected, info] per
    connection; the subscriber's caller id on the publisher's side, the publisher's URI on the subscriber's."""
    talker, listener = node("/talker"), node("/listener")
    received: list[Any] = []
    publisher = talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    _publish_until(publisher, _depth_message(talker), received)
    code, _, rows = xmlrpc.client.ServerProxy(talker.uri).getBusInfo("/rosnode")
    assert code == 1 and [row[1:6] for row in rows] == [["/listener", "o", "TCPROS", "/depth", True]], rows
    code, _, inbound = xmlrpc.client.ServerProxy(listener.uri).getBusInfo("/rosnode")
    assert code == 1 and [row[1:6] for row in inbound] == [[talker.uri, "i", "TCPROS", "/depth", True]], inbound
    assert isinstance(rows[0][0], int) and isinstance(inbound[0][0], int) and rows[0][0] != inbound[0][0]
    pattern = re.compile(r"\w+ connection on port (\d+) to \[(.*) on socket (\d+)\]")  # rosnode's
    assert pattern.fullmatch(rows[0][6]) and pattern.fullmatch(inbound[0][6]), (rows, inbound)
    assert xmlrpc.client.ServerProxy(talker.uri).getBusInfo("/x")[2] == rows


def test_durable_topic_is_latched_for_a_late_subscriber(node: Callable[[str], TcprosTransport]) -> None:
    """/tf_static's QoS (transient local) is a latched ROS 1 topic: published once, before anyone subscribed,
    the message still reaches a subscriber that connects later (and the handshake says latching=1)."""
    talker, listener = node("/talker"), node("/listener")
    publisher = talker.advertise("/tf_depth", IMAGE, TF_STATIC_QOS)
    publisher.publish(_depth_message(talker))
    assert publisher.fields["latching"] == "1"
    assert talker.advertise("/other", IMAGE, OUTPUT_QOS).fields["latching"] == "0"
    received: list[Any] = []
    listener.subscribe("/tf_depth", IMAGE, TF_STATIC_QOS, received.append)
    _wait(lambda: received)
    _check_depth(received[0])


def test_header_seq_counts_each_topics_messages(node: Callable[[str], TcprosTransport]) -> None:
    """As rospy does, a publisher numbers its messages in ``Header.seq`` (1, 2, ...); the caller's message keeps 0."""
    talker, listener = node("/talker"), node("/listener")
    received: list[Any] = []
    listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    publisher = talker.advertise("/depth", IMAGE, SENSOR_QOS)
    message = _depth_message(talker)
    _publish_until(publisher, message, received, 3)
    seqs = [m.header.seq for m in received]
    assert seqs[0] >= 1 and seqs == list(range(seqs[0], seqs[0] + len(seqs))), seqs
    assert message.header.seq == 0
    _check_depth(received[-1])


def test_subscriber_reconnects_after_a_dropped_connection(node: Callable[[str], TcprosTransport]) -> None:
    talker, listener = node("/talker"), node("/listener")
    received: list[Any] = []
    listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    publisher = talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    _publish_until(publisher, _depth_message(talker), received)
    publisher.abort()  # every subscriber connection cut, the node still listed by the master
    time.sleep(0.1)
    count = len(received)
    _publish_until(publisher, _depth_message(talker), received, count + 1)
    _check_depth(received[-1])
    assert publisher.subscriber_count == 1


def test_failed_registration_can_be_retried(master: FakeMaster, node: Callable[[str], TcprosTransport]) -> None:
    talker = node("/talker")
    master.refuse.add("/depth")
    with pytest.raises(TcprosError, match="registerPublisher: '/depth refused'"):
        talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    with pytest.raises(TcprosError, match="registerSubscriber: '/depth refused'"):
        talker.subscribe("/depth", IMAGE, SENSOR_QOS, print)
    master.refuse.clear()
    talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    talker.subscribe("/depth", IMAGE, SENSOR_QOS, print)
    assert master.publishers["/depth"] == master.subscribers["/depth"] == [talker.uri]
    talker.close()
    assert master.publishers["/depth"] == master.subscribers["/depth"] == []


def test_ros2_messages_are_converted(node: Callable[[str], TcprosTransport]) -> None:
    """A ROS 2 store's CameraInfo (lower-case d/k/r/p, no Header.seq) goes out as the ROS 1 message."""
    ros1, ros2 = rosbags_typestore(True), rosbags_typestore(False)
    k = np.array([[30.0, 0, 11.5], [0, 30.0, 7.5], [0, 0, 1]])
    info = CameraInfoData(24, 16, k, np.array([0.1, 0, 0, 0, 0]), np.eye(3), np.hstack([k, np.zeros((3, 1))]))
    info2, info1 = (camera_info_message(ts, info, STAMP, "cam") for ts in (ros2, ros1))
    converted = adopt_message(ros1, info2)
    name = "sensor_msgs/msg/CameraInfo"
    assert bytes(ros1.serialize_ros1(converted, name)) == bytes(ros1.serialize_ros1(info1, name))
    talker, listener = node("/talker"), node("/listener")
    received: list[Any] = []
    listener.subscribe("/info", name, SENSOR_QOS, received.append)
    _publish_until(talker.advertise("/info", name, OUTPUT_QOS), info2, received)
    np.testing.assert_array_equal(received[0].K, k.reshape(-1))


def _raw_subscriber(transport: TcprosTransport, fields: dict[str, str]) -> socket.socket:
    """A hand-made subscriber connection to ``transport``'s TCPROS port, its header sent."""
    proto = xmlrpc.client.ServerProxy(transport.uri).requestTopic("/raw", "/depth", [["TCPROS"]])[2]
    sock = socket.create_connection((proto[1], proto[2]), timeout=5)
    sock.sendall(encode_header(fields) if fields else struct.pack("<I", 0x7FFFFFFF))
    return sock


def test_bad_handshakes_are_one_line_and_refused(
    node: Callable[[str], TcprosTransport], caplog: pytest.LogCaptureFixture
) -> None:
    talker, listener = node("/talker"), node("/listener")
    publisher = talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    caplog.set_level(logging.WARNING, LOGGER)
    with _raw_subscriber(talker, {}) as oversized:  # a header length of 2 GB
        assert oversized.recv(100) == b""
    wrong = {"topic": "/depth", "md5sum": "0" * 32, "callerid": "/wrong\nforged line", "type": "sensor_msgs/Image"}
    with _raw_subscriber(talker, wrong) as sock:
        reply = sock.recv(1000)
    assert b"error=md5sum" in reply
    _wait(lambda: len(caplog.records) >= 2)
    assert "over the limit" in caplog.records[0].getMessage()
    line = caplog.records[1].getMessage()
    assert "/wrong" in line and "md5sum" in line and "\n" not in line  # a peer's text cannot forge log lines
    received: list[Any] = []  # and the publisher goes on
    listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    _publish_until(publisher, _depth_message(talker), received)


def _fake_publisher(frames: list[bytes], md5sum: str) -> tuple[SimpleXMLRPCServer, socket.socket]:
    """A hand-made publisher: an XML-RPC requestTopic and a TCP port that handshakes, then sends ``frames``."""
    listener = socket.create_server(("127.0.0.1", 0))
    api = SimpleXMLRPCServer(("127.0.0.1", 0), logRequests=False)
    port = listener.getsockname()[1]
    api.register_function(lambda caller, topic, protocols: [1, "", ["TCPROS", "127.0.0.1", port]], "requestTopic")
    threading.Thread(target=api.handle_request, daemon=True).start()

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.recv(65536)
            conn.sendall(encode_header({"md5sum": md5sum, "type": "sensor_msgs/Image", "callerid": "/fake"}))
            for frame in frames:
                conn.sendall(struct.pack("<I", len(frame)) + frame)
            time.sleep(0.5)

    threading.Thread(target=serve, daemon=True).start()
    return api, listener


def test_bad_messages_are_one_line_and_skipped(
    master: FakeMaster, node: Callable[[str], TcprosTransport], caplog: pytest.LogCaptureFixture
) -> None:
    listener = node("/listener")
    good = bytes(listener.typestore.serialize_ros1(_depth_message(listener), IMAGE))
    md5 = listener.typestore.generate_msgdef(IMAGE)[1]
    received: list[Any] = []
    caplog.set_level(logging.WARNING, LOGGER)
    listener.subscribe("/depth", IMAGE, SENSOR_QOS, received.append)
    api, tcp = _fake_publisher([good[:-7] + b"\xff" * 3, good], md5)  # truncated, then a good one
    with api, tcp:
        master.registerPublisher("/fake", "/depth", "sensor_msgs/Image", f"http://127.0.0.1:{api.server_address[1]}/")
        _wait(lambda: received)
    _check_depth(received[0])
    assert len(received) == 1
    [record] = caplog.records
    assert record.getMessage().startswith("/depth: dropped a message that is not a valid sensor_msgs/msg/Image")


def test_oversized_message_ends_the_connection(master: FakeMaster, caplog: pytest.LogCaptureFixture) -> None:
    with TcprosTransport(master.uri, "/listener", "127.0.0.1", max_message_bytes=1000) as listener:
        md5 = listener.typestore.generate_msgdef(IMAGE)[1]
        caplog.set_level(logging.WARNING, LOGGER)
        listener.subscribe("/depth", IMAGE, SENSOR_QOS, lambda message: None)
        api, tcp = _fake_publisher([b"\0" * 1001], md5)
        with api, tcp:
            master.registerPublisher(
                "/fake", "/depth", "sensor_msgs/Image", f"http://127.0.0.1:{api.server_address[1]}/"
            )
            _wait(lambda: caplog.records)
    assert "message of 1001 bytes is over the limit of 1000 bytes" in caplog.records[0].getMessage()


def test_slow_subscriber_never_blocks_publish_and_close_is_bounded(node: Callable[[str], TcprosTransport]) -> None:
    """A subscriber that never reads: publish stays fast (drop-oldest per connection), close ends everything."""
    talker = node("/talker")
    publisher = talker.advertise("/depth", IMAGE, QoS(reliable=True, depth=2))
    md5 = publisher.md5sum
    stalled = _raw_subscriber(talker, {"topic": "/depth", "md5sum": md5, "callerid": "/stalled"})
    _wait(lambda: publisher.subscriber_count == 1)
    big = depth_image_message(talker.typestore, np.ones((480, 640), np.float32), STAMP, "cam")
    start = time.monotonic()
    for _ in range(40):  # 49 MB, far more than the socket buffers hold
        publisher.publish(big)
    assert time.monotonic() - start < 2.0
    _wait(lambda: publisher.dropped > 0)
    start = time.monotonic()
    talker.close()
    assert time.monotonic() - start < 3.0
    assert not [t for t in threading.enumerate() if t.name.startswith("tcpros") and t.is_alive()]
    stalled.close()


def test_slave_api(master: FakeMaster, node: Callable[[str], TcprosTransport]) -> None:
    talker = node("/talker")
    talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    proxy = xmlrpc.client.ServerProxy(talker.uri)
    assert proxy.getPid("/x")[0] == 1
    assert proxy.getPublications("/x")[2] == [["/depth", "sensor_msgs/Image"]]
    assert proxy.requestTopic("/x", "/other", [["TCPROS"]])[0] == -1
    assert proxy.requestTopic("/x", "/depth", [["UDPROS"]])[0] == 0
    with pytest.raises(xmlrpc.client.Fault):  # wrong arguments: a fault back, the server goes on
        proxy.requestTopic("/x")
    port = int(talker.uri.rsplit(":", 1)[1].strip("/"))
    broken = b"<?xml version='1.0'?><methodCall><methodName>getPid</methodName><params><param>"
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(b"POST / HTTP/1.0\r\nContent-Length: %d\r\n\r\n" % len(broken) + broken)
        assert sock.recv(100).startswith(b"HTTP/1.0 200")  # an XML-RPC fault, in a 200 reply
    assert proxy.getPid("/x")[0] == 1
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(b"POST / HTTP/1.0\r\nContent-Length: 2000000\r\n\r\n<")  # 2 MB announced: refused unread
        assert sock.recv(100).startswith(b"HTTP/1.0 413")
    assert proxy.shutdown("/x", "asked to")[0] == 1  # as `rosnode kill` does: the node closes itself
    _wait(lambda: master.publishers["/depth"] == [])
    talker.close()  # waits for the shutdown in progress
    _wait(lambda: not [t for t in threading.enumerate() if t.name.startswith("tcpros") and t.is_alive()], 1.0)


def test_bad_arguments(master: FakeMaster, node: Callable[[str], TcprosTransport]) -> None:
    with pytest.raises(InputError, match="ROS master URI"):
        TcprosTransport("127.0.0.1:11311")
    with socket.create_server(("127.0.0.1", 0)) as closed:
        port = closed.getsockname()[1]
    with pytest.raises(TcprosError, match=f"ROS master http://127.0.0.1:{port}/ getUri: .*refused"):
        TcprosTransport(f"http://127.0.0.1:{port}/", timeout=1.0)
    with pytest.raises(InputError, match="ROS host '203.0.113.1' .*cannot listen there"):
        TcprosTransport(master.uri, host="203.0.113.1")  # an address of no interface here (TEST-NET-3)
    talker = node("/talker")
    with pytest.raises(InputError, match="absolute name"):
        talker.advertise("depth", IMAGE, OUTPUT_QOS)
    with pytest.raises(InputError, match="not a ROS 1 Noetic type"):
        talker.advertise("/depth", "sensor_msgs/msg/Nothing", OUTPUT_QOS)
    talker.advertise("/depth", IMAGE, OUTPUT_QOS)
    with pytest.raises(InputError, match="already advertised"):
        talker.advertise("/depth", "sensor_msgs/msg/CameraInfo", OUTPUT_QOS)
    assert MAX_PEERS >= 8
