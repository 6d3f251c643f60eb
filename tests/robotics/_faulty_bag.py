"""A small bag with bad frames among good ones (ROS 1, ROS 2 sqlite3 or MCAP), for the per-frame error tests.

:func:`write_faulty_bag` writes 8 frames of a 64x96 camera and a LiDAR, 0.1 s apart (each scan 2 ms after its
image), with ``CameraInfo`` on ``/cam/camera_info`` and ``/tf_static`` (``cam -> lidar``), so no rig is needed.
Frames 0, 2 and 7 are always good; with every fault (the default) the others are bad:

====== =============== =================================================================================
index  fault           what is wrong (the reason substring of the frame's DataError)
====== =============== =================================================================================
1      ``empty_scan``  every point behind the camera: ``load`` fails (projection), ``check`` passes
3      ``skew``        its scan comes 60 ms late (max skew 50 ms): "no /lidar scan within 50.0 ms"
4      ``truncated``   image data half of ``height * step``: "image holds"
5      ``encoding``    a 16UC1 image: "unsupported image encoding"
6      ``bad_cloud``   a PointCloud2 without z: "PointCloud2 has no z field"
====== =============== =================================================================================

A fault left out of ``bad`` writes that frame good, exactly as ``bad=()`` (the clean bag) writes it, so the
good frames of both bags are equal frame for frame. Every bad frame's error starts with
``f"{path}: /cam/image image {index}: "``.

    >>> bag = write_faulty_bag(tmp_path / "faulty.bag", "ros1")            # doctest: +SKIP
    >>> bag.path, bag.bad[3]                                               # doctest: +SKIP
    (PosixPath('.../faulty.bag'), 'no /lidar scan within 50.0 ms (nearest 60.0 ms apart)')
"""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from semattnet.robotics.bags import CameraInfoData, MessageWriter
from semattnet.robotics.bags.encode import camera_info_message, header, image_message, pointcloud2_message, tf_message

__all__ = ["FAULTS", "FORMATS", "GOOD", "IMAGE_TOPIC", "N_FRAMES", "POINTS_TOPIC", "FaultyBag", "write_faulty_bag"]

IMAGE_TOPIC, POINTS_TOPIC, INFO_TOPIC = "/cam/image", "/lidar", "/cam/camera_info"
#: Frames in the bag, and the indices that are good whatever ``bad`` says.
N_FRAMES, GOOD = 8, (0, 2, 7)
#: fault -> (frame index, the reason substring of its DataError).
FAULTS: dict[str, tuple[int, str]] = {
    "empty_scan": (1, "no point in front of the camera"),
    "skew": (3, "no /lidar scan within 50.0 ms (nearest 60.0 ms apart)"),
    "truncated": (4, "image holds 9216 bytes, 64 rows of 288 need 18432"),
    "encoding": (5, "unsupported image encoding '16UC1'"),
    "bad_cloud": (6, "/lidar message 6: PointCloud2 has no z field"),
}
#: A file or folder name per format (a ROS 1 bag must end in ``.bag``).
FORMATS = {"ros1": "faulty.bag", "sqlite3": "faulty_db3", "mcap": "faulty_mcap"}

T0 = 1_317_000_000 * 10**9
H, W = 64, 96
K = np.array([[60.0, 0.0, 48.0], [0.0, 60.0, 32.0], [0.0, 0.0, 1.0]])
#: LiDAR x forward, y left, z up -> camera x right, y down, z forward.
T_CAM_LIDAR = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0.1], [1, 0, 0, 0], [0, 0, 0, 1]])


class FaultyBag(NamedTuple):
    """What :func:`write_faulty_bag` wrote: the bag, and its bad frames (index -> reason substring)."""

    path: Path
    bad: dict[int, str]


def _points(i: int, behind: bool) -> np.ndarray:
    """(300, 4) float32 LiDAR points of frame ``i`` (x, y, z, intensity), all in front or all behind."""
    rng = np.random.default_rng(100 + i)
    pts = np.column_stack(
        [rng.uniform(3, 30, 300), rng.uniform(-6, 6, 300), rng.uniform(-1.5, 1, 300), rng.uniform(0, 1, 300)]
    ).astype(np.float32)
    if behind:
        pts[:, 0] = -pts[:, 0]
    return pts


def _scan(ts: Any, i: int, t: int, fault: str | None) -> Any:
    pts = _points(i, fault == "empty_scan")
    cols = {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], "intensity": pts[:, 3]}
    if fault == "bad_cloud":
        del cols["z"]
    return pointcloud2_message(ts, cols, t, "lidar")


def _image(ts: Any, i: int, t: int, fault: str | None) -> Any:
    rgb = np.random.default_rng(i).integers(0, 256, (H, W, 3), dtype=np.uint8)
    if fault == "truncated":
        data = rgb.reshape(-1)[: rgb.size // 2]
        return ts.types["sensor_msgs/msg/Image"](
            header=header(ts, t, "cam"), height=H, width=W, encoding="rgb8", is_bigendian=0, step=3 * W, data=data
        )
    if fault == "encoding":
        data = np.zeros(H * W * 2, np.uint8)
        return ts.types["sensor_msgs/msg/Image"](
            header=header(ts, t, "cam"), height=H, width=W, encoding="16UC1", is_bigendian=0, step=2 * W, data=data
        )
    return image_message(ts, rgb, t, "cam")


def write_faulty_bag(path: str | Path, fmt: str, bad: Collection[str] = tuple(FAULTS)) -> FaultyBag:
    """Write the bag of the module doc at ``path`` (must not exist; ``fmt`` ros1 needs a ``.bag`` name) with the
    faults ``bad`` (names of :data:`FAULTS`; ``()``: a clean bag). Returns the path and ``{index: reason}``."""
    path = Path(path)
    unknown = sorted(set(bad) - set(FAULTS))
    if unknown or (fmt == "ros1") != (path.suffix == ".bag"):
        raise ValueError(f"write_faulty_bag: unknown faults {unknown} or a {fmt} bag named {path.name}")
    by_index = {FAULTS[f][0]: f for f in bad}
    info = CameraInfoData(W, H, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam")
    with MessageWriter(path, fmt) as out:
        out.write("/tf_static", T0, tf_message(out.ts, [("cam", "lidar", T_CAM_LIDAR)], T0))
        for i in range(N_FRAMES):
            t, fault = T0 + i * 10**8, by_index.get(i)
            out.write(IMAGE_TOPIC, t, _image(out.ts, i, t, fault))
            out.write(INFO_TOPIC, t, camera_info_message(out.ts, info, t, "cam"))
            ts = t + (60 if fault == "skew" else 2) * 10**6
            out.write(POINTS_TOPIC, ts, _scan(out.ts, i, ts, fault))
    return FaultyBag(path, {FAULTS[f][0]: FAULTS[f][1] for f in bad})
