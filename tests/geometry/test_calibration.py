from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from semattnet.data.io import DataError
from semattnet.geometry import (
    RigCalibration,
    invert_T,
    read_cam_to_cam,
    read_kitti_calibration,
    read_rig_json,
    read_velo_to_cam,
)

from .conftest import RAW_DATE


def _copy_calib(tmp_path: Path) -> Path:
    for name in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt"):
        shutil.copy(RAW_DATE / name, tmp_path / name)
    return tmp_path


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def test_read_cam_to_cam_values() -> None:
    cams = read_cam_to_cam(RAW_DATE / "calib_cam_to_cam.txt")
    assert sorted(cams) == ["00", "01", "02", "03"]
    c2 = cams["02"]
    assert c2.image_size == (1242, 375)
    assert np.allclose(c2.K, [[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]])
    assert c2.P_rect.shape == (3, 4) and c2.P_rect[0, 3] == pytest.approx(44.85728)
    assert c2.R_rect[0, 1] == pytest.approx(1.511453e-02)  # camera 2's own R_rect_02
    # T_cam_rect: t = K^-1 P[:, 3]; t_z = P[2, 3] = 2.745884e-3, t_x = (P[0,3] - cx t_z) / fx.
    t = c2.T_cam_rect[:3, 3]
    assert t[2] == pytest.approx(2.745884e-3)
    assert t[0] == pytest.approx((44.85728 - 609.5593 * 2.745884e-3) / 721.5377)


def test_read_velo_to_cam_values() -> None:
    T = read_velo_to_cam(RAW_DATE / "calib_velo_to_cam.txt")
    assert T.shape == (4, 4) and np.allclose(T[3], [0, 0, 0, 1])
    assert T[0, 1] == pytest.approx(-9.999714e-01) and T[2, 3] == pytest.approx(-2.717806e-01)
    # Same R/T format: the IMU -> Velodyne file reads too.
    assert read_velo_to_cam(RAW_DATE / "calib_imu_to_velo.txt").shape == (4, 4)


@pytest.mark.parametrize("camera", ["02", 3, "03", 2])
def test_kitti_calibration_reproduces_devkit_projection(camera: str | int) -> None:
    cal = read_kitti_calibration(RAW_DATE, camera)
    cam = f"{int(camera):02d}"
    assert isinstance(cal, RigCalibration) and cal.camera == cam and cal.image_size == (1242, 375)
    R00 = np.eye(4)
    R00[:3, :3] = read_cam_to_cam(RAW_DATE / "calib_cam_to_cam.txt")["00"].R_rect
    devkit = read_cam_to_cam(RAW_DATE / "calib_cam_to_cam.txt")[cam].P_rect @ R00 @ cal.T_cam0_lidar
    X = np.c_[np.random.default_rng(0).normal(size=(20, 3)) * 10, np.ones(20)]
    assert np.allclose((cal.K @ (cal.T_cam_lidar @ X.T)[:3]).T, (devkit @ X.T).T, rtol=1e-12, atol=1e-9)


def test_stereo_baseline_between_cameras_2_and_3() -> None:
    T2, T3 = (read_kitti_calibration(RAW_DATE, c).T_cam_lidar for c in ("02", "03"))
    T_cam2_cam3 = T2 @ invert_T(T3)
    # both rectified: same orientation (to the 7 digits of the file's rotations)
    assert np.allclose(T_cam2_cam3[:3, :3], np.eye(3), atol=1e-6)
    assert T_cam2_cam3[0, 3] == pytest.approx(0.532, abs=0.005)  # KITTI's ~0.54 m colour baseline


def test_cam_to_cam_file_path_and_object_style_file_agree(tmp_path: Path) -> None:
    ref = read_kitti_calibration(RAW_DATE, "02")
    assert np.allclose(read_kitti_calibration(RAW_DATE / "calib_cam_to_cam.txt", "02").T_cam_lidar, ref.T_cam_lidar)
    fmt = lambda a: " ".join(f"{v:.12e}" for v in np.ravel(a))  # noqa: E731
    obj = tmp_path / "000005.txt"
    obj.write_text(
        f"P0: {fmt(np.zeros((3, 4)))}\nP2: {fmt(ref.P_rect)}\nR0_rect: {fmt(ref.R_rect_00)}\n"
        f"Tr_velo_to_cam: {fmt(ref.T_cam0_lidar[:3])}\n"
    )
    cal = read_kitti_calibration(obj, 2, image_size=(1242, 375))
    assert np.allclose(cal.T_cam_lidar, ref.T_cam_lidar, atol=1e-12) and np.allclose(cal.K, ref.K)
    with pytest.raises(DataError, match="no camera '03'.*it has 00, 02"):
        read_kitti_calibration(obj, 3)


def test_malformed_numbers(tmp_path: Path) -> None:
    d = _copy_calib(tmp_path)
    _edit(d / "calib_cam_to_cam.txt", "P_rect_02: 7.215377e+02", "P_rect_02: 7.21x377e+02")
    with pytest.raises(DataError, match=r"calib_cam_to_cam.txt: line \d+: malformed numbers for 'P_rect_02'"):
        read_kitti_calibration(d, "02")


def test_missing_key_and_wrong_count(tmp_path: Path) -> None:
    d = _copy_calib(tmp_path)
    _edit(d / "calib_velo_to_cam.txt", "T: -4.069766e-03 ", "T: ")
    with pytest.raises(DataError, match="calib_velo_to_cam.txt: 'T' has 2 numbers, expected 3"):
        read_kitti_calibration(d, "02")
    (d / "calib_velo_to_cam.txt").write_text("R: 1 0 0 0 1 0 0 0 1\n")
    with pytest.raises(DataError, match="missing key 'T'"):
        read_velo_to_cam(d / "calib_velo_to_cam.txt")


def test_unknown_camera_lists_the_available_ones() -> None:
    with pytest.raises(DataError, match="no camera '05'; it has 00, 01, 02, 03"):
        read_kitti_calibration(RAW_DATE, "05")


def test_non_rigid_rotation(tmp_path: Path) -> None:
    d = _copy_calib(tmp_path)
    _edit(d / "calib_velo_to_cam.txt", "R: 7.533745e-03", "R: 2.533745e-01")
    with pytest.raises(DataError, match="calib_velo_to_cam.txt: R: rotation is not orthonormal"):
        read_kitti_calibration(d, "02")
    (d / "calib_velo_to_cam.txt").write_text("R: 1 0 0 0 1 0 0 0 -1\nT: 0 0 0\n")
    with pytest.raises(DataError, match="determinant"):
        read_velo_to_cam(d / "calib_velo_to_cam.txt")


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="calib_cam_to_cam.txt: calibration file not found"):
        read_kitti_calibration(tmp_path, "02")
    (tmp_path / "other.txt").write_text("a: 1 2 3\n")
    with pytest.raises(DataError, match="neither a calib_cam_to_cam file"):
        read_kitti_calibration(tmp_path / "other.txt")


def test_rig_json(tmp_path: Path) -> None:
    ref = read_kitti_calibration(RAW_DATE, "02")
    good = {"K": ref.K.tolist(), "T_cam_lidar": ref.T_cam_lidar.tolist(), "image_size": [1242, 375], "camera": "front"}
    (tmp_path / "rig.json").write_text(json.dumps(good))
    rig = read_rig_json(tmp_path / "rig.json")
    assert rig.image_size == (1242, 375) and rig.camera == "front"
    assert np.allclose(rig.T_cam_lidar, ref.T_cam_lidar) and np.allclose(rig.K, ref.K)
    for change, message in [
        ({"K": None}, "missing key 'K'"),
        ({"T_cam_lidar": np.diag([2.0, 1, 1, 1]).tolist()}, "not a rigid transform"),
        ({"T_cam_lidar": [[1, 0, 0], [0, 1, 0]]}, r"'T_cam_lidar' must be finite numbers of shape \(4, 4\)"),
        ({"image_size": [1242.5, 375]}, "image_size must be two positive integers"),
        ({"K": [["a", 0, 0], [0, 1, 0], [0, 0, 1]]}, "'K' is not a numeric array"),
    ]:
        doc = {k: v for k, v in {**good, **change}.items() if v is not None}
        (tmp_path / "bad.json").write_text(json.dumps(doc))
        with pytest.raises(DataError, match=message):
            read_rig_json(tmp_path / "bad.json")
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(DataError, match="broken.json: not valid JSON"):
        read_rig_json(tmp_path / "broken.json")
