"""``/rosout``: the node's report lines and its ``semattnet.ros`` log as ``rcl_interfaces/msg/Log`` (ROS 2) or
``rosgraph_msgs/Log`` (ROS 1), on rcl's QoS, published from the loop thread, bounded, and off with
``--ros-args --disable-rosout-logs``. (A Cyclone DDS C reader of it: tests/robotics/peers/test_graph_peers.py.)"""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from semattnet.inference.contract import Completion
from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.ros.node import DepthNode, NodeTopics
from semattnet.robotics.ros.ros_args import split_ros_args
from semattnet.robotics.ros.rosout import LOGGERS, MAX_QUEUED, ROSOUT_QOS, Rosout, logger_name

from ._fakes import FakeTransport, deliver_one_frame
from .test_node import _complete

pytest.importorskip("rosbags")

T0 = 1_700_000_000_000_000_000


def _logging_complete(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
    """The node's test completer, logging on the node's logger and a transport's while the loop runs."""
    logging.getLogger("semattnet.ros").warning("a warning of the node's")
    logging.getLogger("semattnet.robotics.ros.tcpros").warning("a peer's fault")
    return _complete(rgb, sparse, semantic)


def _run_one_frame(fake: FakeTransport, rosout: bool = True) -> DepthNode:
    node = DepthNode(
        fake, _logging_complete, NodeTopics(), namespace="/robot", node="depth", report_s=1e-6, rosout=rosout
    )
    node.start()
    deliver_one_frame(fake, T0)
    stop = threading.Event()
    threading.Timer(5.0, stop.set).start()
    try:
        node.spin(stop, frames=1)
    finally:
        stop.set()
        node.close()
    return node


@pytest.mark.parametrize("ros1", [False, True])
def test_the_node_logs_its_report_lines_and_warnings_on_rosout(ros1: bool) -> None:
    fake = FakeTransport()
    if ros1:
        fake.typestore = rosbags_typestore(True)
    _run_one_frame(fake)
    logs = fake.published["/rosout"]
    kind = "rosgraph_msgs/msg/Log" if ros1 else "rcl_interfaces/msg/Log"
    assert logs and all(type(m) is fake.typestore.types[kind] for m in logs)
    assert fake.qos["/rosout"] == ROSOUT_QOS and (ROSOUT_QOS.reliable, ROSOUT_QOS.durable, ROSOUT_QOS.depth) == (
        True,
        True,
        1000,
    )
    info, warn = (2, 4) if ros1 else (20, 30)
    warning = next(m for m in logs if m.msg == "a warning of the node's")
    assert warning.level == warn and warning.function == "_logging_complete" and warning.line > 0
    reports = [m for m in logs if m.level == info]
    assert reports and "frame" in reports[-1].msg  # the summary said at the end
    assert {m.name for m in logs} == {"/robot/depth" if ros1 else "robot.depth"}
    assert any(m.msg == "a peer's fault" and m.level == warn for m in logs)  # the transports' loggers too
    if ros1:
        assert "/robot/depth/output/depth_image" in warning.topics and warning.header.stamp.sec > 0
        assert fake.typestore.serialize_ros1(warning, kind)
    else:
        assert warning.stamp.sec > 0 and fake.typestore.serialize_cdr(warning, kind)
    for name in LOGGERS:  # removed on close
        assert not any(isinstance(h, Rosout) for h in logging.getLogger(name).handlers)


def test_disable_rosout_logs_turns_it_off() -> None:
    _, ros = split_ros_args(["--ros-args", "--disable-rosout-logs"])
    assert ros.rosout is False and split_ros_args(["--ros-args", "--enable-rosout-logs"])[1].rosout is True
    fake = FakeTransport()
    _run_one_frame(fake, rosout=ros.rosout)
    assert "/rosout" not in fake.published and "/diagnostics" in fake.published


def test_the_queue_is_bounded_and_a_failed_publish_is_not_logged_back_into_it() -> None:
    fake = FakeTransport()
    rosout = Rosout(fake, "/depth")
    rosout.advertise()
    for i in range(MAX_QUEUED + 5):
        rosout.line(f"line {i}")
    assert rosout.dropped == 5 and rosout.publish_pending() == MAX_QUEUED
    assert fake.published["/rosout"][0].msg == "line 5"  # the oldest went

    class Broken:
        def publish(self, message: object) -> None:
            raise OSError("no route")

    logger = logging.getLogger("semattnet.ros")
    logger.addHandler(rosout)
    try:
        rosout.publisher = Broken()
        rosout.line("one")
        assert rosout.publish_pending() == 1  # its warning went to stderr, not back into the queue
        assert rosout.publish_pending() == 0
    finally:
        logger.removeHandler(rosout)


def test_logger_names_are_rcls() -> None:
    assert logger_name("/robot/depth") == "robot.depth" and logger_name("/depth") == "depth"


def test_the_terminal_keeps_its_warnings_while_the_node_publishes_them() -> None:
    """With no logging configured (the command line), Python writes warnings to stderr through its last resort;
    the /rosout handler must not silence that while it is attached, and leaves the loggers as they were (in a
    fresh process: pytest configures logging in its own)."""
    script = (
        "import logging\n"
        "from semattnet.robotics.ros.rosout import LOGGERS, Rosout\n"
        "from tests.robotics.ros._fakes import FakeTransport\n"
        "before = [list(logging.getLogger(n).handlers) for n in LOGGERS]\n"
        "rosout = Rosout(FakeTransport(), '/depth')\n"
        "rosout.advertise()\n"
        "rosout.attach()\n"
        "logging.getLogger('semattnet.robotics.ros.tcpros').warning('peer stalled')\n"
        "logging.getLogger('semattnet.ros').warning('frame failed')\n"
        "queued = rosout.publish_pending()\n"
        "rosout.detach()\n"
        "assert [list(logging.getLogger(n).handlers) for n in LOGGERS] == before\n"
        "print(queued)\n"
    )
    root = Path(__file__).resolve().parents[3]
    done = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines() == ["peer stalled", "frame failed"] and done.stdout.strip() == "2"
