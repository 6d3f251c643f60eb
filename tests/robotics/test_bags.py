"""Bags from the bundled KITTI frame: ROS 1, ROS 2 sqlite3 and MCAP; the sparse map equals ``semattnet project``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from semattnet._errors import DataError
from semattnet.cli import main
from semattnet.data.kitti.raw import RawDrive
from semattnet.data.scans import project_scan_file
from semattnet.geometry import project_points, read_kitti_calibration
from semattnet.robotics.bags import (
    BagFailure,
    BagPair,
    BagPairs,
    BagTopics,
    NoTransformError,
    SensorRecord,
    format_topics,
    list_topics,
    write_sensor_bag,
)
from tests._helpers import SAMPLE

pytest.importorskip("rosbags")

RAW = SAMPLE / "kitti_raw" / "2011_09_26"
DRIVE = RAW / "2011_09_26_drive_0035_sync"
SCAN = DRIVE / "velodyne_points" / "data" / "0000000005.bin"
T0 = 1_317_000_000 * 10**9
FORMATS = {"ros1": "drive.bag", "sqlite3": "drive_db3", "mcap": "drive_mcap"}


@pytest.fixture(scope="module")
def frame():  # type: ignore[no-untyped-def]
    return RawDrive(DRIVE, 2).frame("0000000005")


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory, frame) -> dict[str, Path]:  # type: ignore[no-untyped-def]
    """The sample frame three times, 0.1 s apart (scans 3 ms after the images), 40 NaN points per scan."""
    root = tmp_path_factory.mktemp("bags")
    out = {}
    for fmt, name in FORMATS.items():
        recs = [SensorRecord(frame.image, frame.points, T0 + i * 10**8, T0 + i * 10**8 + 3 * 10**6) for i in range(3)]
        compressed = "png" if fmt == "mcap" else None
        imu = read_kitti_calibration(RAW, "02")  # any rigid T_base_lidar; KITTI's own comes from calib_imu_to_velo
        write_sensor_bag(
            root / name, recs, frame.calib, fmt=fmt, nan_points=40, compressed=compressed, T_base_lidar=imu.T_cam0_lidar
        )
        out[fmt] = root / name
    return out


T = BagTopics()


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_topics_listed(bags: dict[str, Path], fmt: str) -> None:
    rows = {r.topic: r for r in list_topics(bags[fmt])}
    assert rows[T.image].msgtype == "sensor_msgs/msg/Image" and rows[T.image].count == 3
    assert rows[T.points].msgtype == "sensor_msgs/msg/PointCloud2" and rows[T.points].count == 3
    assert rows[T.camera_info].count == 3 and rows["/tf_static"].count == 1
    assert rows[T.image].rate_hz == pytest.approx(10.0)
    assert T.points in format_topics(list(rows.values()))


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_pairs_decode_the_frame(bags: dict[str, Path], fmt: str, frame) -> None:  # type: ignore[no-untyped-def]
    pairs = BagPairs(bags[fmt], T.image, T.points)
    assert (pairs.pairing.paired, pairs.pairing.dropped_images, pairs.pairing.unused_scans) == (3, 0, 0)
    assert pairs.pairing.max_skew_ns == 50 * 10**6  # half the 100 ms scan period
    got = list(pairs)
    assert [p.stamp_ns for p in got] == [T0 + i * 10**8 for i in range(3)]
    assert [p.scan_stamp_ns - p.stamp_ns for p in got] == [3 * 10**6] * 3
    p = got[0]
    assert (p.frame_id, p.lidar_frame_id, p.image_size) == ("camera_color_left", "velodyne", (1242, 375))
    assert np.array_equal(p.image, frame.image)
    assert p.points.dtype == np.float32 and np.array_equal(p.points, frame.points)  # NaN points dropped, intensity kept
    assert np.array_equal(p.K, frame.calib.K)  # P_rect_02[:, :3]
    # /tf_static chains velodyne -> base_link -> camera; KITTI's R is orthonormal only to ~5e-8
    assert np.allclose(p.T_cam_lidar, frame.calib.T_cam_lidar, atol=1e-6)


def _png(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path))


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_sparse_equals_project_cli(bags: dict[str, Path], fmt: str, tmp_path: Path) -> None:
    """The bag's scan and calibration projected == `semattnet project` of the .bin with that calibration."""
    p = next(iter(BagPairs(bags[fmt], T.image, T.points)))
    sparse = project_points(p.points, p.K, p.T_cam_lidar, p.image_size)
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps({"K": p.K.tolist(), "T_cam_lidar": p.T_cam_lidar.tolist(), "image_size": p.image_size}))
    out = tmp_path / "cli.png"
    res = CliRunner().invoke(main, ["project", "--points", str(SCAN), "--rig", str(rig), "--out", str(out)])
    assert res.exit_code == 0, res.output
    summary = project_scan_file(SCAN, tmp_path / "lib.png", rig=rig)
    assert np.array_equal(sparse, summary.depth)  # float metres, exactly
    from semattnet.data.io import encode_depth

    assert np.array_equal(_png(out), encode_depth(sparse))
    assert np.count_nonzero(sparse) > 15000


def test_rig_overrides_bag_calibration_and_matches_kitti_project(bags: dict[str, Path], tmp_path: Path) -> None:
    """With KITTI's own calibration as a rig file, the bag gives `project --calib-dir` exactly."""
    cal = read_kitti_calibration(RAW, "02")
    rig = tmp_path / "kitti.json"
    rig.write_text(
        json.dumps({"K": cal.K.tolist(), "T_cam_lidar": cal.T_cam_lidar.tolist(), "image_size": list(cal.image_size)})
    )
    p = next(iter(BagPairs(bags["mcap"], T.image + "/compressed", T.points, rig=rig, tf_topic="/none")))
    assert np.array_equal(p.T_cam_lidar, cal.T_cam_lidar)
    sparse = project_points(p.points, p.K, p.T_cam_lidar, p.image_size)
    out = tmp_path / "cli.png"
    res = CliRunner().invoke(
        main, ["project", "--points", str(SCAN), "--calib-dir", str(RAW), "--camera", "2", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert np.array_equal(sparse, project_scan_file(SCAN, tmp_path / "l.png", calib_dir=RAW).depth)
    from semattnet.data.io import encode_depth

    assert np.array_equal(_png(out), encode_depth(sparse))
    assert p.camera_info.width == 1242 and np.array_equal(p.camera_info.K, cal.K)


def test_compressed_png_topic_is_lossless(bags: dict[str, Path], frame) -> None:  # type: ignore[no-untyped-def]
    p = next(iter(BagPairs(bags["mcap"], T.compressed, T.points)))
    assert np.array_equal(p.image, frame.image)


# --- bad input: one line naming the file / topic ---------------------------------------------------------------


def test_missing_topic(bags: dict[str, Path]) -> None:
    with pytest.raises(DataError, match=r"drive.bag: no topic '/nope' \(topics: .*/kitti/velo/pointcloud"):
        BagPairs(bags["ros1"], "/nope", T.points)


def test_wrong_topic_type(bags: dict[str, Path]) -> None:
    with pytest.raises(DataError, match=r"topic '/kitti/velo/pointcloud' holds sensor_msgs/msg/PointCloud2, expected"):
        BagPairs(bags["ros1"], T.points, T.points)


def test_no_transform_names_both_frames(bags: dict[str, Path]) -> None:
    with pytest.raises(
        NoTransformError,
        match=r"/tf_other: no transform between frames 'velodyne' and "
        r"'camera_color_left'",
    ):
        BagPairs(bags["sqlite3"], T.image, T.points, tf_topic="/tf_other")


def test_no_scan_within_max_skew(bags: dict[str, Path]) -> None:
    with pytest.raises(DataError, match=r"no /kitti/velo/pointcloud scan within 1.0 ms of any .* 3.0 ms apart"):
        BagPairs(bags["mcap"], T.image, T.points, max_skew=0.001)


def test_dropped_images_are_counted(tmp_path: Path, frame) -> None:  # type: ignore[no-untyped-def]
    img, pts = frame.image, frame.points[:2000]
    recs = [
        SensorRecord(img, pts, T0, T0),
        SensorRecord(img, pts, T0 + 10**8, T0 + 10**8),
        SensorRecord(img, pts, T0 + 9 * 10**8, T0 + 2 * 10**8),
    ]
    write_sensor_bag(tmp_path / "b.bag", recs, frame.calib)
    pairs = BagPairs(tmp_path / "b.bag", T.image, T.points)
    assert pairs.pairing.match.tolist() == [0, 1, -1]
    assert (pairs.pairing.dropped_images, pairs.pairing.unused_scans) == (1, 1)
    assert "1 dropped" in pairs.pairing.describe()
    got = list(pairs)  # every image: the one without a scan is a failure, not left out
    assert [p.index for p in got] == [0, 1, 2] and len(pairs) == 3
    assert [type(p) for p in got] == [BagPair, BagPair, BagFailure]
    assert isinstance(got[2], BagFailure) and got[2].name == "0000000002"
    assert str(got[2].error) == (
        f"{tmp_path / 'b.bag'}: {T.image} image 2: no {T.points} scan within 50.0 ms (nearest 700.0 ms apart)"
    )


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_truncated_bag(bags: dict[str, Path], fmt: str, tmp_path: Path) -> None:
    src = bags[fmt]
    files = [src] if src.is_file() else sorted(f for f in src.iterdir() if f.suffix in (".db3", ".mcap"))
    data = files[0].read_bytes()
    bad = tmp_path / files[0].name
    bad.write_bytes(data[: len(data) // 3])
    with pytest.raises(DataError, match=rf"{bad.name}: cannot read the bag \(truncated or corrupt\?\)"):
        pairs = BagPairs(bad, T.image, T.points)
        list(pairs)


def test_missing_bag(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="nothing.bag: bag not found"):
        list_topics(tmp_path / "nothing.bag")


# --- the command line --------------------------------------------------------------------------------------------


def test_cli_bag_from_kitti_and_topics(tmp_path: Path, frame) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "k_mcap"
    res = CliRunner().invoke(
        main, ["data", "bag-from-kitti", "--drive", str(DRIVE), "--out", str(out), "--nan-points", "7"]
    )
    assert res.exit_code == 0, res.output
    assert "/kitti/velo/pointcloud 1" in res.output
    res = CliRunner().invoke(main, ["data", "bag-topics", str(out)])
    assert res.exit_code == 0 and "sensor_msgs/msg/CameraInfo" in res.output
    p = next(iter(BagPairs(out, T.image, T.points)))
    assert np.array_equal(p.points, frame.points)
    # KITTI's base_link (the IMU, calib_imu_to_velo.txt) in between; the chain gives KITTI's T_cam_lidar
    assert np.allclose(p.T_cam_lidar, frame.calib.T_cam_lidar, atol=1e-6)
    again = CliRunner().invoke(main, ["data", "bag-from-kitti", "--drive", str(DRIVE), "--out", str(out)])
    assert again.exit_code != 0 and "exists" in again.output and len(again.output.strip().splitlines()) == 1
