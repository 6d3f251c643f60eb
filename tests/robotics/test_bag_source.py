"""BagSource: frames of ROS 1, ROS 2 sqlite3 and MCAP bags built from the bundled KITTI frame."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from semattnet._errors import DataError
from semattnet.cli import main
from semattnet.data.io import encode_depth
from semattnet.data.kitti.raw import RawDrive
from semattnet.data.scans import project_scan_file
from semattnet.data.sources import RawDriveSource
from semattnet.geometry import read_kitti_calibration
from semattnet.palette import ids_to_colors
from semattnet.robotics import BagSource
from semattnet.robotics.bags import BagTopics, SensorRecord, write_sensor_bag
from tests.inference._raw_sample import DRIVE, RAW_DATE, SCAN

pytest.importorskip("rosbags")

T0 = 1_317_000_000 * 10**9 + 123_456_789
FORMATS = {"ros1": "drive.bag", "sqlite3": "drive_db3", "mcap": "drive_mcap"}
T = BagTopics()


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The sample frame twice, 0.1 s apart, scans 3 ms after the images, 40 NaN points per scan (intensity kept)."""
    frame = RawDrive(DRIVE, 2).frame("0000000005")
    root = tmp_path_factory.mktemp("bags")
    recs = [SensorRecord(frame.image, frame.points, T0 + i * 10**8, T0 + i * 10**8 + 3 * 10**6) for i in range(2)]
    imu = read_kitti_calibration(RAW_DATE, "02")  # an intermediate base_link frame in /tf_static
    for fmt, name in FORMATS.items():
        write_sensor_bag(root / name, recs, frame.calib, fmt=fmt, nan_points=40, T_base_lidar=imu.T_cam0_lidar)
    return {fmt: root / name for fmt, name in FORMATS.items()}


def kitti_rig(path: Path) -> Path:
    """KITTI's own camera-02 calibration as a rig JSON (a bag's /tf_static quaternions cannot reproduce it bit for
    bit, so exactness against the KITTI path goes through the rig)."""
    cal = read_kitti_calibration(RAW_DATE, "02")
    path.write_text(
        json.dumps({"K": cal.K.tolist(), "T_cam_lidar": cal.T_cam_lidar.tolist(), "image_size": list(cal.image_size)})
    )
    return path


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_sparse_equals_project_cli_exactly(bags: dict[str, Path], fmt: str, tmp_path: Path) -> None:
    logged: list[str] = []
    source = BagSource(bags[fmt], T.image, T.points, rig=kitti_rig(tmp_path / "rig.json"), log=logged.append)
    assert source.names == ["0000000000", "0000000001"]
    assert "2 image(s) paired" in logged[0] and "0 dropped" in logged[0] and "0 of 2 scan(s) unused" in logged[0]
    out = tmp_path / "cli.png"
    res = CliRunner().invoke(
        main, ["project", "--points", str(SCAN), "--calib-dir", str(RAW_DATE), "--camera", "2", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    reference = project_scan_file(SCAN, tmp_path / "lib.png", calib_dir=RAW_DATE).depth
    raw = RawDriveSource(DRIVE, "5").load("0000000005")
    for i, frame in enumerate(source):
        assert np.array_equal(frame.sparse, reference)  # float metres, bit for bit
        assert np.array_equal(encode_depth(frame.sparse), np.asarray(Image.open(out)))
        assert np.array_equal(frame.sparse, raw.sparse) and np.array_equal(frame.rgb, raw.rgb)
        assert np.array_equal(frame.points, raw.points) and np.array_equal(frame.K, raw.K)
        assert frame.meta.stamp_ns == T0 + i * 10**8 and frame.timestamp == pytest.approx((T0 + i * 10**8) / 1e9)
        assert (frame.meta.frame_id, frame.meta.lidar_frame_id) == ("camera_color_left", "velodyne")
        assert frame.meta.scan_stamp_ns == T0 + i * 10**8 + 3 * 10**6
        assert frame.meta.camera_info is not None and frame.meta.camera_info.image_size == (1242, 375)


def test_tf_static_calibration_and_random_access(bags: dict[str, Path]) -> None:
    """Without a rig the /tf_static chain (velodyne -> base_link -> camera) is used; loads in any order agree."""
    source = BagSource(bags["mcap"], T.image, T.points)
    first, second = source.load("0000000001"), source.load("0000000000")  # backwards: the bag is read again
    assert np.array_equal(first.rgb, second.rgb) and np.array_equal(first.sparse, second.sparse)
    assert np.allclose(first.calib.T_cam_lidar, read_kitti_calibration(RAW_DATE, "02").T_cam_lidar, atol=1e-6)
    assert np.count_nonzero(first.sparse) > 15000
    assert source.inputs()[0] == bags["mcap"]


def _semantic_bag(path: Path, offsets_ms: list[int], bad: int | None = None) -> tuple[Path, list[np.ndarray]]:
    """A 24x32 bag: 3 images, 3 scans, CameraInfo, and semantic colour images ``offsets_ms`` after each image
    (semantic message ``bad`` in an unsupported encoding)."""
    from semattnet.robotics.bags import CameraInfoData, MessageWriter
    from semattnet.robotics.bags.encode import camera_info_message, image_message, pointcloud2_message

    K = np.array([[30.0, 0, 16], [0, 30.0, 12], [0, 0, 1]])
    info = CameraInfoData(32, 24, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam")
    rng = np.random.default_rng(0)
    sems = [ids_to_colors(rng.integers(0, 19, (24, 32))) for _ in range(3)]
    pts = {"x": np.array([5.0, 6.0], np.float32), "y": np.zeros(2, np.float32), "z": np.zeros(2, np.float32)}
    with MessageWriter(path, "sqlite3") as out:
        for i in range(3):
            t = T0 + i * 10**8
            out.write("/cam/image", t, image_message(out.ts, np.full((24, 32, 3), 9 * i, np.uint8), t, "cam"))
            out.write("/cam/camera_info", t, camera_info_message(out.ts, info, t, "cam"))
            out.write("/lidar", t, pointcloud2_message(out.ts, pts, t, "lidar"))
            ts = t + offsets_ms[i] * 10**6
            sem = image_message(out.ts, sems[i], ts, "cam")
            if i == bad:
                sem.encoding = "16UC1"
            out.write("/cam/semantic", ts, sem)
    rig = path.parent / "rig.json"
    T_cam_lidar = [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]]
    rig.write_text(json.dumps({"K": K.tolist(), "T_cam_lidar": T_cam_lidar, "image_size": [32, 24]}))
    return rig, sems


def test_semantic_topic_paired_by_stamp(tmp_path: Path) -> None:
    rig, sems = _semantic_bag(tmp_path / "b", [0, 2, -1])
    source = BagSource(tmp_path / "b", "/cam/image", "/lidar", rig=rig, semantic_topic="/cam/semantic")
    frames = [source.load(n) for n in ("0000000002", "0000000000", "0000000001")]
    assert [f.name for f in frames] == ["0000000002", "0000000000", "0000000001"]
    for f in frames:
        assert np.array_equal(f.semantic, sems[int(f.name)])
    assert np.count_nonzero(frames[0].sparse) == 1  # (5, 0, 0) and (6, 0, 0) land on the same pixel: nearest wins
    assert frames[0].sparse[12, 16] == np.float32(5.0)


def test_semantic_topic_too_far_fails_that_frame_only(tmp_path: Path) -> None:
    rig, sems = _semantic_bag(tmp_path / "b", [0, 0, 30])
    logged: list[str] = []
    source = BagSource(
        tmp_path / "b",
        "/cam/image",
        "/lidar",
        rig=rig,
        semantic_topic="/cam/semantic",
        max_skew=0.02,
        log=logged.append,
    )
    assert source.names == ["0000000000", "0000000001", "0000000002"]
    assert "semantic maps from /cam/semantic (1 image(s) without one within 20.0 ms)" in logged[0]
    with pytest.raises(DataError) as err:
        source.load("0000000002")
    assert str(err.value) == (
        f"{tmp_path / 'b'}: /cam/image image 2: no /cam/semantic semantic image within 20.0 ms (nearest 30.0 ms apart)"
    )
    assert np.array_equal(source.load("0000000001").semantic, sems[1])
    (tmp_path / "c").mkdir()
    rig, _ = _semantic_bag(tmp_path / "c" / "b", [30, 30, 30])  # none near enough: nothing to complete
    with pytest.raises(DataError, match=r"no /cam/semantic semantic image within 20.0 ms of any /cam/image image"):
        BagSource(tmp_path / "c" / "b", "/cam/image", "/lidar", rig=rig, semantic_topic="/cam/semantic", max_skew=0.02)
    with pytest.raises(DataError, match=r"no topic '/cam/nope'"):
        BagSource(tmp_path / "b", "/cam/image", "/lidar", rig=rig, semantic_topic="/cam/nope")


def test_undecodable_semantic_image_fails_its_frame_only(tmp_path: Path) -> None:
    rig, sems = _semantic_bag(tmp_path / "b", [0, 2, -1], bad=1)
    source = BagSource(tmp_path / "b", "/cam/image", "/lidar", rig=rig, semantic_topic="/cam/semantic")
    assert np.array_equal(source.load("0000000000").semantic, sems[0])
    for _ in range(2):  # asked again (check, then load): the same error
        with pytest.raises(DataError) as err:
            source.load("0000000001")
        assert str(err.value) == (
            f"{tmp_path / 'b'}: /cam/image image 1: /cam/semantic message 1: unsupported image "
            "encoding '16UC1' (semattnet reads rgb8, bgr8, rgba8, bgra8, mono8)"
        )
    assert np.array_equal(source.load("0000000002").semantic, sems[2])
