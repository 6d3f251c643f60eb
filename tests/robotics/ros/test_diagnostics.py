"""``/diagnostics``: the node's health as a ``diagnostic_msgs/DiagnosticArray`` every report interval and on stop,
with the documented keys and OK / WARN / ERROR as docs/guides/ros2-node.md says."""

from __future__ import annotations

import re
import threading
from pathlib import Path

import pytest

from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.ros.diagnostics import ERROR, KEYS, OK, STALE, WARN, Diagnostics, NodeHealth
from semattnet.robotics.ros.node import DepthNode, NodeTopics

from ._fakes import FakeTransport, deliver_one_frame
from .test_node import _complete

pytest.importorskip("rosbags")

GUIDE = Path(__file__).resolve().parents[3] / "docs" / "guides" / "ros2-node.md"
T0 = 1_700_000_000_000_000_000


def health(done: int = 0, failed: int = 0, stale: int = 0, images: int = 0, scans: int = 0) -> NodeHealth:
    received = {"image": images, "scan": scans, "camera_info": images}
    return NodeHealth(done, failed, stale, 0, 0, received, {"network": (12.0, 20.0)}, ("image", "scan"))


def test_levels_follow_the_inputs_and_the_frames() -> None:
    clock = [0.0]
    diag = Diagnostics(FakeTransport(), "/robot/depth", 1.0, clock=lambda: clock[0])

    def level(h: NodeHealth) -> tuple[int, str, dict[str, str]]:
        clock[0] += 1.0
        return diag.status(h, clock[0])

    assert level(health(1, images=10, scans=10))[0] == OK
    lv, text, values = level(health(11, images=20, scans=20))
    assert (lv, values["rate_hz"], values["frames_completed"], values["since_image_s"]) == (OK, "10.00", "11", "0.00")
    assert level(health(12, stale=3, images=30, scans=30))[:2] == (WARN, "3 pair(s) dropped")
    assert level(health(12, stale=3, images=30, scans=40))[:2] == (WARN, "no image in the interval")
    assert level(health(12, failed=2, stale=3, images=40, scans=50))[:2] == (ERROR, "2 frame(s) failed, none completed")
    level(health(12, failed=2, stale=3, images=40, scans=60))
    level(health(12, failed=2, stale=3, images=40, scans=65))
    lv, text, values = level(health(12, failed=2, stale=3, images=40, scans=70))
    assert (lv, text, values["since_image_s"]) == (ERROR, "no image for 3 report intervals", "3.00")
    assert values["latency_network_mean_ms"] == "12.0" and values["latency_network_max_ms"] == "20.0"


def test_an_input_that_never_came_is_an_error_after_three_intervals() -> None:
    clock = [0.0]
    diag = Diagnostics(FakeTransport(), "/semattnet", 2.0, clock=lambda: clock[0])
    clock[0] = 2.0
    assert diag.status(health(), 2.0)[0] == WARN
    lv, text, values = diag.status(health(), 6.0)
    assert (lv, text, values["since_scan_s"]) == (ERROR, "no image, scan for 3 report intervals", "never")


@pytest.mark.parametrize("ros1", [False, True])
def test_the_node_publishes_its_status_every_interval_and_stale_on_stop(ros1: bool) -> None:
    fake = FakeTransport()
    if ros1:
        fake.typestore = rosbags_typestore(True)
    node = DepthNode(fake, _complete, NodeTopics(), namespace="/robot", node="depth", report_s=1e-6).start()
    deliver_one_frame(fake, T0)
    stop = threading.Event()
    threading.Timer(5.0, stop.set).start()
    node.spin(stop, frames=1)
    stop.set()
    arrays = fake.published["/diagnostics"]
    assert arrays, "no /diagnostics"
    last = arrays[-1]
    assert type(last) is fake.typestore.types["diagnostic_msgs/msg/DiagnosticArray"]
    (status,) = last.status
    assert (status.name, status.hardware_id, status.level) == ("semattnet: /robot/depth", "/robot/depth", STALE)
    values = {kv.key: kv.value for kv in status.values}
    assert set(KEYS) <= set(values) and values["frames_completed"] == "1" and values["received_image"] == "1"


def test_the_guide_documents_every_key() -> None:
    text = GUIDE.read_text(encoding="utf-8")
    documented = set(re.findall(r"`(\w+)`", text))
    assert set(KEYS) <= documented, sorted(set(KEYS) - documented)
    assert "latency_STAGE_mean_ms" in text and "/diagnostics" in text


def test_the_node_types_are_registered_from_their_msg_text_where_rosbags_lacks_them() -> None:
    """A store without diagnostic_msgs and rmw_dds_common (an older rosbags) gets them from Humble's .msg text,
    field for field as rosbags' own Humble store defines them."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from semattnet.robotics.bags.deps import NODE_MSGS, add_missing_types

    humble = rosbags_typestore(False)
    bare = get_typestore(Stores.EMPTY)
    bare.register(get_types_from_msg("int32 sec\nuint32 nanosec", "builtin_interfaces/msg/Time"))
    bare.register(get_types_from_msg("builtin_interfaces/Time stamp\nstring frame_id", "std_msgs/msg/Header"))
    add_missing_types(bare)
    for name in NODE_MSGS:
        assert bare.fielddefs[name] == humble.fielddefs[name], name
