"""One robot frame and one topic table: what the bag writes is what a live node publishes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet.data.frames import Frame, SensorMeta
from semattnet.inference.contract import Completion
from semattnet.inference.sinks import predict_frame
from semattnet.robotics.bags import BagWriter, CameraInfoData, open_bag
from semattnet.robotics.frame import ROS_TYPES, RobotFrame, topic_names

pytest.importorskip("rosbags")

K = np.array([[40.0, 0, 7.5], [0, 40.0, 4.5], [0, 0, 1]])
INFO = CameraInfoData(16, 10, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam_in", 5)
STAMP = 1_317_000_000_123_456_789


def _prediction() -> object:
    depth = np.full((10, 16), 4.0, np.float32)
    depth[0, :3] = 0  # holes
    rgb = np.full((10, 16, 3), 9, np.uint8)
    meta = SensorMeta(stamp_ns=STAMP, frame_id="cam_left", lidar_frame_id="velo", camera_info=INFO)
    frame = Frame("f", rgb, np.zeros((10, 16), np.float32), K=K, meta=meta)
    with pytest.warns(UserWarning, match="3 hole"):  # the PNG's note on holes
        return predict_frame(frame, Completion(depth))


def test_topic_table_is_the_bags() -> None:
    assert topic_names("/semattnet", tuple(ROS_TYPES)) == {
        "depth": "/semattnet/depth_image",
        "points": "/semattnet/point_cloud",
        "uncertainty": "/semattnet/uncertainty",
        "camera_info": "/semattnet/camera_info",
    }


def test_bag_holds_the_frames_messages(tmp_path: Path) -> None:
    """The bag's bytes per topic are the CDR of RobotFrame.messages: one builder for both."""
    robot = RobotFrame.of(_prediction())  # type: ignore[arg-type]
    assert (robot.stamp_ns, robot.frame_id, robot.lidar_frame_id) == (STAMP, "cam_left", "velo")
    assert np.isnan(robot.depth[0, :3]).all() and robot.depth[5, 5] == 4.0 and len(robot.cloud.xyz) == 160 - 3
    with BagWriter(tmp_path / "bag") as writer:
        writer.write_frame(robot)
        ts = writer._out.ts  # type: ignore[union-attr]
    want = {writer.topics[k]: bytes(ts.serialize_cdr(m, ROS_TYPES[k])) for k, m in robot.messages(ts).items()}
    with open_bag(tmp_path / "bag") as reader:
        got = {c.topic: bytes(raw) for c, _, raw in reader.messages()}
    assert got == want and set(got) == {"/semattnet/depth_image", "/semattnet/point_cloud", "/semattnet/camera_info"}
