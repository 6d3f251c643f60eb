"""Synthetic drives written as KITTI raw drives: read by the raw readers unchanged, geometry consistent."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import read_depth, read_image
from semattnet.data.kitti.raw import RawDrive
from semattnet.data.sources.raw_drive import project_frame
from semattnet.geometry import invert_T, project_points, read_kitti_calibration, read_oxts_motion, transform_points
from semattnet.geometry.calibration import read_velo_to_cam
from semattnet.synthetic.drive import BASELINE, FRAME_RATE, STEP, oxts_pose, write_synthetic_drives

FRAMES, SIZE = 3, (96, 224)


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("drives")
    write_synthetic_drives(out, drives=1, frames=FRAMES, size=SIZE, seed=5, domain="target")
    return out


def _drive(tree: Path) -> Path:
    return tree / "kitti_raw" / "2000_01_01" / json.loads((tree / "drives.json").read_text())["drives"][0]["drive"]


def _gt(tree: Path, drive: Path, name: str) -> np.ndarray:
    return read_depth(
        tree / "data_depth_annotated" / "train" / drive.name / "proj_depth" / "groundtruth" / "image_02" / f"{name}.png"
    )


def test_the_raw_reader_reads_every_frame_and_the_scan_agrees_with_the_ground_truth(tree: Path) -> None:
    drive = _drive(tree)
    raw = RawDrive(drive, camera=2)
    assert raw.names == [f"{k:010d}" for k in range(FRAMES)]
    assert raw.calib.image_size == SIZE[::-1]
    for frame in raw:
        assert frame.points.dtype == np.float32 and frame.points.shape[1] == 4 and len(frame.points) > 300
        assert 0 < frame.points[:, 3].min() and frame.points[:, 3].max() <= 1  # reflectance
        sparse, gt = project_frame(frame), _gt(tree, drive, frame.name)
        both = (sparse > 0) & (gt > 0)
        assert both.sum() > 50
        # sub-pixel positions on the steep near road, 2 cm range noise; a few points see past edges
        assert np.mean(np.abs(sparse[both] - gt[both]) < 0.05 * gt[both]) > 0.93
    assert RawDrive(drive, camera=3).frame("0000000000").image.shape == (*SIZE, 3)
    from semattnet.data.kitti.splits import KittiDepthCompletion  # the same frames as a depth-completion train split

    split = KittiDepthCompletion(tree, "train")
    assert len(split) == FRAMES
    np.testing.assert_allclose(split[0]["sparse"][0].numpy(), project_frame(raw.frame("0000000000")), atol=1 / 512)


def test_the_right_image_is_the_left_seen_from_the_baseline(tree: Path) -> None:
    """Warping image_03 with the true depth and the calibration's baseline gives image_02 (but for occlusions
    and the 8 % image noise); a wrong baseline does not."""
    drive = _drive(tree)
    cal2, cal3 = read_kitti_calibration(drive.parent, "02"), read_kitti_calibration(drive.parent, "03")
    baseline = (cal2.T_cam_lidar @ invert_T(cal3.T_cam_lidar))[0, 3]
    assert baseline == pytest.approx(BASELINE, abs=1e-9)
    left, right = (read_image(drive / f"image_0{c}" / "data" / "0000000001.png").astype(float) for c in (2, 3))
    gt = _gt(tree, drive, "0000000001")
    v, u = np.nonzero(gt > 0)

    def error(b: float) -> float:
        col = np.round(u - cal2.K[0, 0] * b / gt[v, u]).astype(int)
        ok = (col >= 0) & (col < SIZE[1])
        return float(np.abs(right[v[ok], col[ok]] - left[v[ok], u[ok]]).mean())

    assert error(BASELINE) < 0.6 * error(0.0) and error(BASELINE) < 0.6 * error(2 * BASELINE)


def test_oxts_poses_move_the_scan_onto_the_next_frame(tree: Path) -> None:
    """The OXTS packets give 1 m forward per frame (the pose and the velocity read_oxts_motion reads agree); with
    the imu -> velo -> camera calibration they move frame 1's scan onto frame 0's ground truth."""
    drive = _drive(tree)
    packets = [
        [float(x) for x in (drive / "oxts" / "data" / f"{k:010d}.txt").read_text().split()] for k in range(FRAMES)
    ]
    assert all(len(p) == 30 for p in packets)
    poses = [oxts_pose(p) for p in packets]
    step = invert_T(poses[0]) @ poses[1]
    np.testing.assert_allclose(step, [[1, 0, 0, STEP], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], atol=1e-6)
    motion = read_oxts_motion(drive / "oxts" / "data" / "0000000000.txt")
    np.testing.assert_allclose(motion.velocity / FRAME_RATE, step[:3, 3], atol=1e-6)
    assert motion.yaw_rate == 0.0
    T_velo_imu = read_velo_to_cam(drive.parent / "calib_imu_to_velo.txt")
    cal = read_kitti_calibration(drive.parent, "02")
    T_0_1 = cal.T_cam_lidar @ T_velo_imu @ step @ invert_T(T_velo_imu)  # frame-1 LiDAR -> frame-0 camera
    scan1 = RawDrive(drive).frame("0000000001").points
    moved = project_points(scan1, cal.K, T_0_1, SIZE[::-1])
    gt0 = _gt(tree, drive, "0000000000")
    both = (moved > 0) & (gt0 > 0)
    assert both.sum() > 50 and np.mean(np.abs(moved[both] - gt0[both]) < 0.03 * gt0[both]) > 0.9
    assert transform_points(T_0_1, np.zeros((1, 3)))[0, 2] > 0.9  # frame 1's LiDAR is ahead of frame 0's camera


@pytest.mark.slow
def test_predict_reads_the_drive_and_metrics_scores_it(tree: Path, tmp_path: Path) -> None:
    drive = _drive(tree)
    r = CliRunner().invoke(
        main, ["predict", "--kitti-raw", str(drive), "--method", "classical", "--out", str(tmp_path / "pred")]
    )
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in (tmp_path / "pred").glob("0*[0-9].png")) == [f"{k:010d}.png" for k in range(FRAMES)]
    gt_dir = tree / "data_depth_annotated" / "train" / drive.name / "proj_depth" / "groundtruth" / "image_02"
    m = CliRunner().invoke(main, ["metrics", str(tmp_path / "pred"), str(gt_dir), "--json", str(tmp_path / "m.json")])
    assert m.exit_code == 0, m.output
    scores = json.loads((tmp_path / "m.json").read_text())
    assert scores["images"] == FRAMES and 0 < scores["rmse_mm"] < 20_000


def test_drives_are_deterministic_and_refuse_a_full_folder(tree: Path, tmp_path: Path) -> None:
    again = write_synthetic_drives(tmp_path / "a", drives=1, frames=2, size=SIZE, seed=5, domain="target")
    first = _drive(tree)
    assert again["drives"][0]["drive"] == first.name
    for rel in ("image_02/data/0000000001.png", "image_03/data/0000000001.png", "velodyne_points/data/0000000001.bin"):
        assert (tmp_path / "a" / "kitti_raw" / "2000_01_01" / first.name / rel).read_bytes() == (
            first / rel
        ).read_bytes()
    with pytest.raises(FileExistsError, match="not empty"):
        write_synthetic_drives(tmp_path / "a", drives=1, frames=1, size=SIZE)
    with pytest.raises(ValueError, match="unknown synthetic domain"):
        write_synthetic_drives(tmp_path / "b", domain="mars")


def test_a_drive_of_several_streets_leaves_a_frame_out_between_them(tmp_path: Path) -> None:
    from semattnet.synthetic.drive import STREET_GAP

    m = write_synthetic_drives(tmp_path, drives=1, frames=2, size=(32, 64), seed=1, streets=2)
    drive = _drive(tmp_path)
    assert RawDrive(drive).names == ["0000000000", "0000000001", "0000000003", "0000000004"]
    assert m["drives"][0]["frames"] == 4 and len(set(m["drives"][0]["seeds"])) == 2  # type: ignore[arg-type]
    read = [
        oxts_pose([float(x) for x in (drive / "oxts" / "data" / f"{k:010d}.txt").read_text().split()]) for k in (1, 3)
    ]
    assert (invert_T(read[0]) @ read[1])[0, 3] == pytest.approx(STREET_GAP - STEP, abs=1e-5)
    assert len((drive / "oxts" / "timestamps.txt").read_text().splitlines()) == 5
