"""An in-process transport and the messages a robot sends, for the node's tests."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from semattnet.geometry import make_T
from semattnet.robotics.bags.decode import CameraInfoData
from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.bags.encode import camera_info_message, image_message, pointcloud2_message, tf_message
from semattnet.robotics.ros.transport import QoS

TS = rosbags_typestore(False)
H, W = 12, 16
K = np.array([[20.0, 0, 7.5], [0, 20.0, 5.5], [0, 0, 1]])
INFO = CameraInfoData(W, H, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam", 0)
#: LiDAR x forward -> camera z forward (a KITTI-like rig), 0.1 m apart.
T_CAM_LIDAR = make_T(np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]]), np.array([0.0, -0.1, 0]))


class FakeTransport:
    """Delivers what the test hands it; records what the node publishes."""

    name = "fake"

    def __init__(self) -> None:
        self.typestore = TS
        self.subs: dict[str, tuple[str, QoS, Callable[[object], None]]] = {}
        self.published: dict[str, list[object]] = {}
        self.qos: dict[str, QoS] = {}
        self.closed = False

    def advertise(self, topic: str, msgtype: str, qos: QoS) -> _Pub:
        self.published[topic], self.qos[topic] = [], qos
        return _Pub(self.published[topic])

    def subscribe(self, topic: str, msgtype: str, qos: QoS, callback: Callable[[object], None]) -> None:
        self.subs[topic] = (msgtype, qos, callback)

    def deliver(self, topic: str, msg: object) -> None:
        self.subs[topic][2](msg)

    def close(self) -> None:
        self.closed = True


class _Pub:
    def __init__(self, sink: list[object]) -> None:
        self.sink = sink

    def publish(self, message: object) -> None:
        self.sink.append(message)


def image(stamp: int, frame_id: str = "cam") -> object:
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 1] = 100
    return image_message(TS, rgb, stamp, frame_id)


def points() -> np.ndarray:
    """LiDAR points 10 m ahead (x forward), spread over the image."""
    y, z = np.meshgrid(np.linspace(-3, 3, 7), np.linspace(-2, 2, 5))
    return np.stack([np.full(y.size, 10.0), y.ravel(), z.ravel()], 1).astype(np.float32)


def scan(stamp: int, pts: np.ndarray | None = None, frame_id: str = "velo") -> object:
    p = points() if pts is None else pts
    return pointcloud2_message(TS, {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]}, stamp, frame_id)


def camera_info(stamp: int = 0, info: CameraInfoData = INFO) -> object:
    return camera_info_message(TS, info, stamp, "cam")


def tf_static() -> object:
    return tf_message(TS, [("cam", "velo", T_CAM_LIDAR)], 0)


def deliver_one_frame(fake: FakeTransport, stamp: int, node: str = "/robot/depth") -> None:
    """What a rig sends the node ``node`` for one frame: its CameraInfo, ``/tf_static``, an image and a scan 5 ms
    after it."""
    for topic, message in (
        (f"{node}/input/camera_info", camera_info()),
        ("/tf_static", tf_static()),
        (f"{node}/input/image", image(stamp)),
        (f"{node}/input/point_cloud", scan(stamp + 5_000_000)),
    ):
        fake.deliver(topic, message)
