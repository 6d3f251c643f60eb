"""The DDS transport in one process over loopback: ROS 2 wire names, rosbags' CDR bytes, QoS."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS

pytest.importorskip("cyclonedds")
pytest.importorskip("rosbags")

from semattnet.robotics.bags.encode import depth_image_message
from semattnet.robotics.ros.dds import DdsTransport, dds_topic, dds_type_name, loopback_config


def test_wire_names() -> None:
    assert dds_topic("/robot1/semattnet/output/depth_image") == "rt/robot1/semattnet/output/depth_image"
    assert dds_type_name("sensor_msgs/msg/Image") == "sensor_msgs::msg::dds_::Image_"
    assert '<NetworkInterface name="lo"/>' in loopback_config(3) and "<AllowMulticast>false" in loopback_config(3)
    with pytest.raises(InputError, match="absolute ROS name"):
        dds_topic("depth")
    with pytest.raises(InputError, match="--domain-id: expected 0-232, got 300"):
        DdsTransport(300)


class _Configured(Exception):
    """Raised by the stand-in domain: the configuration was seen, no participant made."""


@pytest.mark.parametrize(
    ("loopback", "uri", "kind"), [(False, "", "network"), (True, "", "loopback"), (False, "x.xml", None)]
)
def test_the_socket_buffers_are_asked_for_on_every_network_unless_the_user_configures_cyclone(
    monkeypatch: pytest.MonkeyPatch, loopback: bool, uri: str, kind: str | None
) -> None:
    """4 MB socket buffers on a robot's network too (Cyclone's other defaults kept), on lo with the loopback
    settings; a CYCLONEDDS_URI of the user's rules alone."""
    from semattnet.robotics.ros import dds

    seen: list[str] = []

    def configure(domain_id: int, config: str) -> None:
        seen.append(config)
        raise _Configured

    monkeypatch.setattr(dds, "_open_domain", configure)
    monkeypatch.setenv("CYCLONEDDS_URI", uri)
    import cyclonedds.domain

    def participant(*args: object, **kwargs: object) -> None:  # reached only when no domain of ours was made
        raise _Configured

    monkeypatch.setattr(cyclonedds.domain, "DomainParticipant", participant)
    with pytest.raises(_Configured):
        DdsTransport(7, loopback=loopback)
    if kind is None:
        assert seen == []
        return
    (config,) = seen
    assert '<SocketReceiveBufferSize min="default" max="4MB"/>' in config and 'Domain id="7"' in config
    assert ('<NetworkInterface name="lo"/>' in config) == (kind == "loopback")
    assert ("AllowMulticast" in config) == (kind == "loopback")
    assert config == (dds.loopback_config(7) if loopback else dds.network_config(7))


def test_image_round_trip_is_rosbags_cdr() -> None:
    """A reliable keep-last-1 writer to a best-effort reader: the message arrives whole, stamp and frame id kept,
    and the DDS type holds no ``uint8`` (octets), so Cyclone 0.10 peers can parse it."""
    a, b = DdsTransport(41, loopback=True), DdsTransport(41, loopback=True)
    got: list[object] = []
    arrived = threading.Event()
    try:
        b.subscribe("/t/depth", "sensor_msgs/msg/Image", SENSOR_QOS, lambda m: (got.append(m), arrived.set()))
        pub = a.advertise("/t/depth", "sensor_msgs/msg/Image", OUTPUT_QOS)
        depth = np.arange(48 * 64, dtype=np.float32).reshape(48, 64) / 7 + 1
        msg = depth_image_message(a.typestore, depth, 1_700_000_000_123_456_789, "cam_left")
        for _ in range(50):  # discovery takes a moment: publish until the reader has one
            pub.publish(msg)
            if arrived.wait(0.05):
                break
    finally:
        a.close()
        b.close()
    assert got, "nothing arrived in 2.5 s"
    out = got[0]
    assert out.header == msg.header and (out.width, out.height, out.encoding) == (64, 48, "32FC1")  # type: ignore[attr-defined]
    np.testing.assert_array_equal(np.frombuffer(out.data.tobytes(), "<f4").reshape(48, 64), depth)  # type: ignore[attr-defined]
    from cyclonedds.idl.types import byte

    image_type = a._types.struct("sensor_msgs/msg/Image")
    assert image_type.__annotations__["is_bigendian"] is byte


def test_garbage_and_callback_errors_are_one_line(caplog: pytest.LogCaptureFixture) -> None:
    """Bytes that are no Image, and a callback that raises, are one logged line each; nothing propagates."""
    import logging

    t = DdsTransport(42, loopback=True)
    try:
        with caplog.at_level(logging.WARNING, logger="semattnet.robotics.ros.dds"):
            t._deliver("/t/img", "sensor_msgs/msg/Image", b"\x00\x01\x00\x00\xff\xff", lambda m: None)
            t._deliver(
                "/t/img",
                "sensor_msgs/msg/Image",
                bytes(t.typestore.serialize_cdr(_image(t), "sensor_msgs/msg/Image")),
                lambda m: (_ for _ in ()).throw(MemoryError("too big")),
            )
    finally:
        t.close()
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and lines[0].startswith("/t/img: cannot deserialise a sensor_msgs/msg/Image (6 bytes)")
    assert lines[1] == "/t/img: MemoryError: too big"


def _image(t: DdsTransport) -> object:
    return depth_image_message(t.typestore, np.ones((2, 3), np.float32), 5, "cam")


def test_ros_discovery_info_names_the_node_and_its_endpoints_gids() -> None:
    """A reader of ``ros_discovery_info`` whose types are declared here from rmw_dds_common's Humble .msg text (not
    from rosbags) gets the node's namespace, name and the GIDs of its readers and writers: each the DDS entity's
    GUID padded with 8 zero bytes, as rmw_cyclonedds makes them; the node's end empties the participant's nodes."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.idl import annotations, make_idl_struct
    from cyclonedds.idl.types import array, bounded_str, byte, sequence
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    def struct(name: str, fields: dict[str, object]) -> type:
        return annotations.final(make_idl_struct(name, f"rmw_dds_common::msg::dds_::{name}_", fields))

    gid_t = struct("Gid", {"data": array[byte, 24]})  # char[24] data
    node_t = struct(
        "NodeEntitiesInfo",
        {
            "node_namespace": bounded_str[256],
            "node_name": bounded_str[256],
            "reader_gid_seq": sequence[gid_t],
            "writer_gid_seq": sequence[gid_t],
        },
    )
    info_t = struct("ParticipantEntitiesInfo", {"gid": gid_t, "node_entities_info_seq": sequence[node_t]})

    keeper = DdsTransport(43, loopback=True, node_name="peer")  # the loopback domain outlives the node's close
    node = DdsTransport(43, loopback=True, namespace="/robot", node_name="depth")
    guid = node.guid
    try:
        depth = node.advertise("/robot/depth/output/depth_image", "sensor_msgs/msg/Image", OUTPUT_QOS)
        node.subscribe("/camera/image_raw", "sensor_msgs/msg/Image", SENSOR_QOS, lambda m: None)
        peer = DomainParticipant(43)
        qos = Qos(Policy.Reliability.Reliable(0), Policy.Durability.TransientLocal, Policy.History.KeepAll)
        reader = DataReader(peer, Topic(peer, "ros_discovery_info", info_t), qos=qos)
        infos: list[Any] = []
        for _ in range(100):
            infos += [s for s in reader.take(N=8) if isinstance(s, info_t) and bytes(s.gid.data)[:16] == guid]
            if infos:
                break
            threading.Event().wait(0.05)
        assert infos, "no ros_discovery_info in 5 s"
        info = infos[-1]
        pad = bytes(8)
        assert bytes(info.gid.data) == guid + pad
        (entry,) = info.node_entities_info_seq
        assert (entry.node_namespace, entry.node_name) == ("/robot", "depth")
        assert [bytes(g.data) for g in entry.writer_gid_seq] == [depth.guid.bytes + pad]
        assert len(entry.reader_gid_seq) == 1 and bytes(entry.reader_gid_seq[0].data).endswith(pad)
        assert node.graph.readers == [bytes(entry.reader_gid_seq[0].data)[:16]]
    finally:
        node.close()
    for _ in range(100):
        left = [s for s in reader.take(N=8) if isinstance(s, info_t) and bytes(s.gid.data)[:16] == guid]
        if left:
            assert left[-1].node_entities_info_seq == []
            break
        threading.Event().wait(0.05)
    else:
        pytest.fail("no announcement of the node's end")
    peer.__del__()
    keeper.close()


def test_a_latched_topic_reaches_a_late_reader() -> None:
    """``--latch-camera-info``'s QoS (reliable, transient local, depth 1): a reader that comes after the only
    message was written still gets it, as a late ``ros2 topic echo --qos-durability transient_local`` does."""
    import time

    from semattnet.robotics.ros.transport import LATCHED_QOS

    a, b = DdsTransport(43, loopback=True), DdsTransport(43, loopback=True)
    got: list[object] = []
    arrived = threading.Event()
    try:
        pub = a.advertise("/t/info", "sensor_msgs/msg/Image", LATCHED_QOS)
        pub.publish(_image(a))  # before any reader exists
        time.sleep(0.2)
        b.subscribe("/t/info", "sensor_msgs/msg/Image", LATCHED_QOS, lambda m: (got.append(m), arrived.set()))
        arrived.wait(5.0)
    finally:
        a.close()
        b.close()
    assert len(got) == 1 and got[0].header.stamp.nanosec == 5  # type: ignore[attr-defined]
