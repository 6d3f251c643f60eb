"""Camera/LiDAR calibration readers (KITTI raw, KITTI object-style, JSON rig files).

Frames: ``lidar`` (Velodyne), ``cam0`` (unrectified reference camera 0), ``rect`` (rectified cam0) and
``cam2``/``cam3`` (the rectified colour cameras; rectified cameras all share the ``rect`` orientation).

KITTI raw gives ``T_cam0_lidar`` (``calib_velo_to_cam.txt``: ``R``, ``T``), the rectifying rotation
``R_rect_00`` and, per camera X, ``P_rect_0X = K [I | t_X]`` (3x4). The devkit projects a LiDAR point with
``P_rect_0X @ R_rect_00 @ T_cam0_lidar @ p``; only ``R_rect_00`` is used whatever the camera, because the
``P_rect_0X`` already live in the rectified cam0 frame. Splitting ``P_rect_0X`` into ``K`` and a translation::

    t_X = K^-1 P_rect_0X[:, 3]            i.e. t_z = P[2,3], t_y = (P[1,3] - cy t_z) / fy,
                                               t_x = (P[0,3] - cx t_z) / fx
    T_camX_rect  = [[I, t_X], [0, 1]]     (a pure translation: the stereo baseline)
    T_camX_lidar = T_camX_rect @ R_rect_00 (as 4x4) @ T_cam0_lidar

so that ``K @ (T_camX_lidar @ p)[:3] == P_rect_0X @ R_rect_00 @ T_cam0_lidar @ p`` exactly. (The shortcut
``t = (P[0,3]/fx, P[1,3]/fy, P[2,3])`` is off by ``cx t_z / fx`` ~ 2 mm for KITTI's camera 2.)
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.bounds import check_image_size, regular_file
from semattnet._utils.documents import read_document

from .transforms import check_rigid, check_rotation, make_T

__all__ = [
    "CameraCalibration",
    "RigCalibration",
    "read_cam_to_cam",
    "read_kitti_calibration",
    "read_projection",
    "read_rig_json",
    "read_velo_to_cam",
]

#: Keys of KITTI calibration files whose values are text, not numbers.
_TEXT_KEYS = {"calib_time"}


@dataclass(frozen=True)
class CameraCalibration:
    """One rectified KITTI camera from ``calib_cam_to_cam.txt``.

    Attributes:
        camera: "00".."03".
        K: (3, 3) intrinsics in pixels, ``P_rect[:, :3]``.
        P_rect: (3, 4) projection from the rectified cam0 frame to this camera's pixels.
        R_rect: (3, 3) this camera's ``R_rect_0X`` (LiDAR projection uses ``R_rect_00`` for every camera).
        image_size: (width, height) in pixels of the rectified image (``S_rect_0X``).
    """

    camera: str
    K: np.ndarray
    P_rect: np.ndarray
    R_rect: np.ndarray
    image_size: tuple[int, int]

    @property
    def T_cam_rect(self) -> np.ndarray:
        """(4, 4) translation from the rectified cam0 frame to this camera: ``t = K^-1 P_rect[:, 3]``."""
        return make_T(np.eye(3), np.linalg.solve(self.K, self.P_rect[:, 3]))


@dataclass(frozen=True)
class RigCalibration:
    """What projecting LiDAR points into one camera needs.

    Attributes:
        K: (3, 3) intrinsics in pixels.
        T_cam_lidar: (4, 4) LiDAR frame -> (rectified) camera frame, metres.
        image_size: (width, height) in pixels, or None when the source does not say.
        camera: camera id ("02", ...) or a free name; None if unknown.
        P_rect, R_rect_00, T_cam0_lidar: the KITTI pieces ``T_cam_lidar`` was built from (None otherwise).
        source: the file(s) it was read from.
    """

    K: np.ndarray
    T_cam_lidar: np.ndarray
    image_size: tuple[int, int] | None
    camera: str | None = None
    P_rect: np.ndarray | None = None
    R_rect_00: np.ndarray | None = None
    T_cam0_lidar: np.ndarray | None = None
    source: str = ""


def _read_kv(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """``key: numbers`` lines of a KITTI calibration file as float64 vectors (text keys skipped)."""
    path = regular_file(path, "calibration file")
    out: dict[str, np.ndarray] = {}
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text calibration file (byte {exc.start} is not UTF-8)") from None
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, rest = line.partition(":")
        key = key.strip()
        if not sep:
            raise DataError(f"{path}: line {n}: expected 'key: values', got {line.strip()[:40]!r}")
        if key in _TEXT_KEYS:
            continue
        try:
            out[key] = np.array([float(v) for v in rest.split()], dtype=np.float64)
        except ValueError:
            raise DataError(f"{path}: line {n}: malformed numbers for {key!r}: {rest.strip()[:60]!r}") from None
        if not np.all(np.isfinite(out[key])):
            raise DataError(f"{path}: line {n}: {key!r} contains NaN or infinite values")
    return out


def _get(kv: dict[str, np.ndarray], key: str, shape: tuple[int, ...], path: Path) -> np.ndarray:
    if key not in kv:
        raise DataError(f"{path}: missing key {key!r}")
    v = kv[key]
    if v.size != int(np.prod(shape)):
        raise DataError(f"{path}: {key!r} has {v.size} numbers, expected {int(np.prod(shape))} for {shape}")
    return v.reshape(shape)


def _check_R(R: np.ndarray, what: str, path: Path) -> np.ndarray:
    why = check_rotation(R)
    if why:
        raise DataError(f"{path}: {what}: {why}")
    return R


def _check_K(K: np.ndarray, what: str, path: Path) -> np.ndarray:
    if not np.all(np.isfinite(K)):
        raise DataError(f"{path}: {what} has NaN or infinite entries")
    if not (K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1]) and K[1, 0] == 0):
        raise DataError(f"{path}: {what} is not a pinhole camera matrix (need fx, fy > 0, last row 0 0 1)")
    return K


def read_projection(path: str | os.PathLike[str], camera: str = "02") -> np.ndarray:
    """The (3, 4) rectified projection ``P_rect_<camera>`` of a KITTI ``calib_cam_to_cam.txt``, pixels, alone:
    ``K = P[:, :3]``, ``P[:, 3]`` = ``K @ t`` the offset from the rectified cam0 (the stereo baseline). Unlike
    :func:`read_cam_to_cam` it needs no ``R_rect`` / ``S_rect`` (files written for intrinsics only have none).

    Raises:
        DataError: missing file or key, malformed numbers, or not a pinhole matrix.
    """
    path = Path(path)
    P = _get(_read_kv(path), f"P_rect_{camera}", (3, 4), path)
    _check_K(P[:, :3], f"P_rect_{camera}", path)
    return P


def read_cam_to_cam(path: str | os.PathLike[str]) -> dict[str, CameraCalibration]:
    """Read a KITTI raw ``calib_cam_to_cam.txt``.

    Args:
        path: the file.

    Returns:
        ``{"00": CameraCalibration, ...}`` for every camera with ``P_rect_0X`` (needs ``R_rect_0X``, ``S_rect_0X``).

    Raises:
        DataError: missing file/key, malformed numbers, a non-rotation ``R_rect``, or no camera at all.
    """
    path = Path(path)
    kv = _read_kv(path)
    cams = sorted(k[len("P_rect_") :] for k in kv if k.startswith("P_rect_"))
    if not cams:
        raise DataError(f"{path}: no P_rect_XX entry (not a calib_cam_to_cam file?)")
    out = {}
    for cam in cams:
        P = _get(kv, f"P_rect_{cam}", (3, 4), path)
        K = _check_K(P[:, :3].copy(), f"P_rect_{cam}", path)
        R = _check_R(_get(kv, f"R_rect_{cam}", (3, 3), path), f"R_rect_{cam}", path)
        w, h = _get(kv, f"S_rect_{cam}", (2,), path)
        out[cam] = CameraCalibration(cam, K, P, R, check_image_size(w, h, f"{path}: S_rect_{cam}"))
    return out


def read_velo_to_cam(path: str | os.PathLike[str]) -> np.ndarray:
    """Read ``calib_velo_to_cam.txt`` (``R``: 9 numbers row-major, ``T``: 3 numbers, metres).

    Returns:
        (4, 4) float64 ``T_cam0_lidar``. Works for any file of that ``R``/``T`` form (e.g. imu_to_velo).

    Raises:
        DataError: missing file/key, malformed numbers, or ``R`` not a rotation.
    """
    path = Path(path)
    kv = _read_kv(path)
    R = _check_R(_get(kv, "R", (3, 3), path), "R", path)
    return make_T(R, _get(kv, "T", (3,), path))


def _camera_id(camera: str | int) -> str:
    return f"{int(camera):02d}" if str(camera).isdigit() else str(camera)


def _from_cam_to_cam(cam_file: Path, velo_file: Path, camera: str) -> RigCalibration:
    cams = read_cam_to_cam(cam_file)
    if camera not in cams:
        raise DataError(f"{cam_file}: no camera {camera!r}; it has {', '.join(cams)}")
    if "00" not in cams:
        raise DataError(f"{cam_file}: no R_rect_00/P_rect_00 entry (camera 00 defines the rectified frame)")
    T_cam0_lidar = read_velo_to_cam(velo_file)
    cal, R00 = cams[camera], cams["00"].R_rect
    T_cam_lidar = cal.T_cam_rect @ make_T(R00, np.zeros(3)) @ T_cam0_lidar
    return RigCalibration(
        cal.K, T_cam_lidar, cal.image_size, camera, cal.P_rect, R00, T_cam0_lidar, f"{cam_file}, {velo_file}"
    )


def _from_object_calib(path: Path, camera: str, image_size: tuple[int, int] | None) -> RigCalibration:
    """KITTI object/odometry-style single file: ``P0..P3``, ``R0_rect``, ``Tr_velo_to_cam`` (3x4)."""
    kv = _read_kv(path)
    key = f"P{int(camera)}" if camera.isdigit() else camera
    if key not in kv:
        have = ", ".join(f"{int(k[1:]):02d}" for k in sorted(kv) if k[:1] == "P" and k[1:].isdigit())
        raise DataError(f"{path}: no camera {camera!r} ({key}); it has {have or 'none'}")
    P = _get(kv, key, (3, 4), path)
    K = _check_K(P[:, :3].copy(), key, path)
    R00 = _check_R(_get(kv, "R0_rect", (3, 3), path), "R0_rect", path)
    Tr = _get(kv, "Tr_velo_to_cam", (3, 4), path)
    T_cam0_lidar = make_T(_check_R(Tr[:, :3], "Tr_velo_to_cam", path), Tr[:, 3])
    T_cam_rect = make_T(np.eye(3), np.linalg.solve(K, P[:, 3]))
    T_cam_lidar = T_cam_rect @ make_T(R00, np.zeros(3)) @ T_cam0_lidar
    return RigCalibration(K, T_cam_lidar, image_size, camera, P, R00, T_cam0_lidar, str(path))


def read_kitti_calibration(
    path: str | os.PathLike[str], camera: str | int = "02", image_size: tuple[int, int] | None = None
) -> RigCalibration:
    """LiDAR -> rectified camera ``camera`` calibration from KITTI files.

    Args:
        path: a raw-data date folder (or a per-frame ``calib/`` folder) holding ``calib_cam_to_cam.txt`` and
            ``calib_velo_to_cam.txt``; or a ``calib_cam_to_cam.txt`` with ``calib_velo_to_cam.txt`` beside it;
            or an object/odometry-style file with ``P0..P3``, ``R0_rect``, ``Tr_velo_to_cam``.
        camera: "00".."03" (or 0..3).
        image_size: (width, height); only used for object-style files, which do not store it.

    Returns:
        :class:`RigCalibration` with ``T_cam_lidar = T_cam_rect @ R_rect_00 @ T_cam0_lidar`` (see module doc).

    Raises:
        DataError: missing files or keys, malformed numbers, an unknown camera (the message lists those present).
    """
    path, camera = Path(path), _camera_id(camera)
    if path.is_dir():
        return _from_cam_to_cam(path / "calib_cam_to_cam.txt", path / "calib_velo_to_cam.txt", camera)
    if not path.is_file():
        raise DataError(f"{path}: calibration file or folder not found")
    keys = _read_kv(path)
    if any(k.startswith("P_rect_") for k in keys):
        return _from_cam_to_cam(path, path.with_name("calib_velo_to_cam.txt"), camera)
    if "Tr_velo_to_cam" in keys:
        return _from_object_calib(path, camera, image_size)
    raise DataError(f"{path}: neither a calib_cam_to_cam file (P_rect_XX) nor an object-style file (Tr_velo_to_cam)")


def read_rig_json(path: str | os.PathLike[str]) -> RigCalibration:
    """A non-KITTI rig: ``{"K": 3x3, "T_cam_lidar": 4x4, "image_size": [w, h], "camera": optional name}``.

    Also reads ``.yaml``/``.yml`` with the same keys when PyYAML is installed. Units: pixels and metres.

    Raises:
        DataError: unreadable file, missing key, wrong shape, non-finite numbers, non-rigid ``T_cam_lidar``.
    """
    path = regular_file(path, "rig file")
    doc = read_document(path)  # JSON or YAML, bounded in size and nesting, no YAML aliases
    if not isinstance(doc, dict):
        raise DataError(f"{path}: expected an object with keys K, T_cam_lidar, image_size")
    vals = {}
    for key, shape in (("K", (3, 3)), ("T_cam_lidar", (4, 4)), ("image_size", (2,))):
        if key not in doc:
            raise DataError(f"{path}: missing key {key!r}")
        try:
            vals[key] = np.array(doc[key], dtype=np.float64)
        except (TypeError, ValueError, OverflowError):  # OverflowError: an integer of 400 digits
            raise DataError(f"{path}: {key!r} is not a numeric array") from None
        if vals[key].shape != shape or not np.all(np.isfinite(vals[key])):
            raise DataError(f"{path}: {key!r} must be finite numbers of shape {shape}, got {vals[key].shape}")
    _check_K(vals["K"], "K", path)
    why = check_rigid(vals["T_cam_lidar"])
    if why:
        raise DataError(f"{path}: T_cam_lidar is not a rigid transform: {why}")
    w, h = vals["image_size"]
    size = check_image_size(w, h, f"{path}: image_size")
    name = doc.get("camera")
    return RigCalibration(vals["K"], vals["T_cam_lidar"], size, None if name is None else str(name), source=str(path))
