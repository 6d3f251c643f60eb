"""Decoders (Image, CompressedImage, PointCloud2 layouts, CameraInfo), the transform tree and pairing."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from semattnet._errors import DataError, MissingDependencyError
from semattnet._utils.extras import require
from semattnet.geometry import make_T
from semattnet.robotics.bags import (
    NoTransformError,
    TransformTree,
    decode_compressed_image,
    decode_image,
    decode_pointcloud2,
    pair_stamps,
)
from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.bags.encode import compressed_image_message, image_message
from semattnet.robotics.bags.tf import matrix_to_quaternion, quaternion_to_matrix

pytest.importorskip("rosbags")


def _img(enc: str, h: int, w: int, step: int, data: np.ndarray) -> NS:
    return NS(encoding=enc, height=h, width=w, step=step, data=data)


def test_image_encodings_and_step_padding() -> None:
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    padded = np.zeros((2, 12), np.uint8)  # step 12 > 3 * 3
    padded[:, :9] = rgb[..., ::-1].reshape(2, 9)
    assert np.array_equal(decode_image(_img("bgr8", 2, 3, 12, padded.reshape(-1)), "/t"), rgb)
    assert np.array_equal(decode_image(_img("rgb8", 2, 3, 9, rgb.reshape(-1)), "/t"), rgb)
    mono = decode_image(_img("mono8", 2, 3, 4, np.array([1, 2, 3, 0, 4, 5, 6, 0], np.uint8)), "/t")
    assert mono.shape == (2, 3, 3) and mono[1, 2].tolist() == [6, 6, 6]
    with pytest.raises(DataError, match=r"^/cam: unsupported image encoding 'nv21' \(semattnet reads rgb8"):
        decode_image(_img("nv21", 2, 3, 6, np.zeros(12, np.uint8)), "/cam")
    with pytest.raises(DataError, match=r"^/cam: image holds 5 bytes"):
        decode_image(_img("rgb8", 2, 3, 9, np.zeros(5, np.uint8)), "/cam")


def test_image_message_round_trip_and_compressed() -> None:
    ts = rosbags_typestore(False)
    rgb = np.random.default_rng(0).integers(0, 255, (4, 5, 3), dtype=np.uint8)
    msg = ts.deserialize_cdr(
        ts.serialize_cdr(image_message(ts, rgb, 7, "cam"), "sensor_msgs/msg/Image"), "sensor_msgs/msg/Image"
    )
    assert np.array_equal(decode_image(msg, "/t"), rgb) and msg.header.frame_id == "cam"
    assert np.array_equal(decode_compressed_image(compressed_image_message(ts, rgb, 7, "cam", "png"), "/t"), rgb)
    jpg = decode_compressed_image(compressed_image_message(ts, rgb, 7, "cam", "jpeg"), "/t")
    assert jpg.shape == rgb.shape
    with pytest.raises(DataError, match=r"^/c: cannot decode the compressed image"):
        decode_compressed_image(NS(format="jpeg", data=np.zeros(10, np.uint8)), "/c")


def _cloud(
    fields: list[tuple[str, int, str]],
    step: int,
    pts: dict[str, np.ndarray],
    big: bool = False,
    row_pad: int = 0,
    height: int = 1,
) -> NS:
    """A PointCloud2-like message: fields (name, offset, numpy type), ``step`` bytes per point."""
    n = len(next(iter(pts.values())))
    order = ">" if big else "<"
    dt = np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [order + f[2] for f in fields],
            "offsets": [f[1] for f in fields],
            "itemsize": step,
        }
    )
    arr = np.zeros(n, dt)
    for k, v in pts.items():
        arr[k] = v
    width = n // height
    rows = np.frombuffer(arr.tobytes(), np.uint8).reshape(height, width * step)
    rows = np.hstack([rows, np.full((height, row_pad), 0xAB, np.uint8)])
    codes = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}
    pf = [NS(name=f[0], offset=f[1], datatype=codes[f[2]], count=1) for f in fields]
    return NS(
        height=height,
        width=width,
        fields=pf,
        is_bigendian=big,
        point_step=step,
        row_step=width * step + row_pad,
        data=rows.reshape(-1),
        is_dense=False,
    )


XYZ = {"x": np.array([1.0, np.nan, 3.0, 4.0]), "y": np.array([5.0, 6.0, 7.0, 8.0]), "z": np.array([9.0, 1, 2, np.inf])}


@pytest.mark.parametrize("big", [False, True])
def test_pointcloud2_any_layout(big: bool) -> None:
    # float64 z first, padding, an extra ring field, intensity uint16, point_step > fields, row padding, 2 rows
    fields = [("z", 0, "f8"), ("ring", 8, "u2"), ("x", 12, "f4"), ("intensity", 16, "u2"), ("y", 20, "f4")]
    msg = _cloud(
        fields, 32, {**XYZ, "ring": np.arange(4), "intensity": np.array([10, 20, 30, 40])}, big=big, row_pad=5, height=2
    )
    pts = decode_pointcloud2(msg, "/velo")
    assert pts.dtype == np.float64  # z is float64
    assert pts.tolist() == [[1.0, 5.0, 9.0, 10.0], [3.0, 7.0, 2.0, 30.0]]  # NaN and inf points dropped


def test_pointcloud2_float32_without_intensity() -> None:
    msg = _cloud([("x", 0, "f4"), ("y", 4, "f4"), ("z", 8, "f4")], 16, XYZ)
    pts = decode_pointcloud2(msg, "/velo")
    assert pts.dtype == np.float32 and pts.shape == (2, 3)


def test_pointcloud2_errors() -> None:
    with pytest.raises(DataError, match=r"^/velo: PointCloud2 has no z field \(fields: x, y, rgb\)"):
        decode_pointcloud2(_cloud([("x", 0, "f4"), ("y", 4, "f4"), ("rgb", 8, "f4")], 12, {"x": np.ones(2)}), "/velo")
    with pytest.raises(DataError, match=r"^/velo: PointCloud2 field 'x' must be FLOAT32 or FLOAT64"):
        decode_pointcloud2(_cloud([("x", 0, "i4"), ("y", 4, "f4"), ("z", 8, "f4")], 12, {"x": np.ones(2)}), "/velo")
    short = _cloud([("x", 0, "f4"), ("y", 4, "f4"), ("z", 8, "f4")], 12, {"x": np.ones(3)})
    short.data = short.data[:20]
    with pytest.raises(DataError, match=r"^/velo: PointCloud2 holds 20 bytes"):
        decode_pointcloud2(short, "/velo")


def _rot(axis: int, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def test_quaternions_round_trip() -> None:
    for R in (np.eye(3), _rot(0, 179.0), _rot(1, -90.0), _rot(2, 33.0) @ _rot(0, 120.0)):
        q = matrix_to_quaternion(R)
        assert q[3] >= 0 and np.allclose(quaternion_to_matrix(q), R, atol=1e-12)
    assert np.allclose(matrix_to_quaternion(_rot(2, 90.0)), [0, 0, np.sqrt(0.5), np.sqrt(0.5)])


def test_transform_tree_chains_both_ways() -> None:
    T_base_lidar = make_T(_rot(2, 10.0), np.array([0.5, 0.0, 1.7]))
    T_base_cam = make_T(_rot(0, -90.0) @ _rot(2, 5.0), np.array([1.0, 0.2, 1.5]))
    T_cam_lens = make_T(np.eye(3), np.array([0.0, 0.0, 0.01]))
    tree = TransformTree("/tf_static")
    tree.add("/base_link", "velodyne", T_base_lidar)
    tree.add("base_link", "camera", T_base_cam)
    tree.add("camera", "lens", T_cam_lens)
    want = np.linalg.inv(T_base_cam @ T_cam_lens) @ T_base_lidar
    assert np.allclose(tree.lookup("lens", "velodyne"), want, atol=1e-12)
    assert np.allclose(tree.lookup("velodyne", "lens"), np.linalg.inv(want), atol=1e-12)
    assert np.array_equal(tree.lookup("camera", "camera"), np.eye(4))
    tree.add("map", "odom", np.eye(4))
    want = r"^/tf_static: no transform between frames 'velodyne' and 'odom' \(frames: base_link, camera, lens, map"
    with pytest.raises(NoTransformError, match=want):
        tree.lookup("odom", "velodyne")


def test_pair_stamps_nearest_within_half_period() -> None:
    p = pair_stamps(np.array([0, 49, 51, 160, 1000]), np.array([0, 100, 200]))
    assert p.match.tolist() == [0, 0, 1, 2, -1] and p.max_skew_ns == 50
    assert (p.paired, p.dropped_images, p.unused_scans) == (4, 1, 0)
    assert pair_stamps(np.array([150]), np.array([100, 200])).match.tolist() == [0]  # a tie takes the earlier scan
    assert pair_stamps(np.array([0, 500]), np.array([0, 100]), max_skew_ns=1000).match.tolist() == [0, 1]
    one = pair_stamps(np.array([0, 60_000_000]), np.array([10]))  # one scan: a 100 ms period is assumed
    assert one.max_skew_ns == 50_000_000 and one.match.tolist() == [0, -1]


def test_missing_extra_is_one_line() -> None:
    with pytest.raises(
        MissingDependencyError, match=r"^writing X needs the optional package 'no_such_pkg_xyz': pip install"
    ):
        require("no_such_pkg_xyz.sub", "writing X")
    with pytest.raises(MissingDependencyError, match=r"pip install 'semattnet\[rerun\]'"):
        require("rerun.no_such_module_xyz", "logging")
