"""Synthetic drives: a car with a domain's rig drives down a synthetic street, written as KITTI raw drives.

A drive is one scene (the street, its light: :func:`~.scenes.make_scene`) seen from a car that moves
:data:`STEP` metres straight along the street per frame at :data:`FRAME_RATE` Hz (KITTI: ~1 m at 10 Hz).
Every frame has the left image (camera 02), the right image (camera 03, :data:`BASELINE` to the right,
rectified: same intrinsics and orientation), the LiDAR's own sweep in its frame and the exact ground
truth of camera 02. Every frame draws its image noise, LiDAR and ground-truth sampling from its own
generator, so frame ``k`` of a drive is the same whatever the number of frames.

:func:`write_synthetic_drives` writes them as KITTI raw drives (``kitti_raw/DATE/DATE_drive_NNNN_sync``:
``image_02/data``, ``image_03/data``, ``velodyne_points/data/*.bin`` (float32 x, y, z, reflectance),
``oxts/data/*.txt``, timestamps; ``calib_cam_to_cam.txt``, ``calib_velo_to_cam.txt``,
``calib_imu_to_velo.txt`` in the date folder), so :class:`~semattnet.data.kitti.raw.RawDrive` reads them
unchanged, and beside them as a KITTI depth-completion ``train`` split (``data_depth_velodyne``,
``data_depth_annotated``, ``semantic``) for scoring.

Poses: the OXTS packets put the car (the IMU, which sits at the LiDAR, level) on a straight road heading
east from :data:`ORIGIN_LAT_LON`; :func:`oxts_pose` turns a packet back into the (4, 4) IMU pose in KITTI's
Mercator frame (the devkit's ``convertOxtsToPose``), and the forward velocity and yaw rate (fields ``vf``,
``wu``) are those :func:`semattnet.geometry.read_oxts_motion` reads.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np
import numpy.typing as npt

from semattnet._utils.outputs import mark_tree
from semattnet.data.kitti import layout
from semattnet.geometry.transforms import invert_T, make_T

from .domain import Domain, Pose, get_domain
from .layout import Box
from .lidar import LidarScan, lidar_to_camera, simulate_lidar
from .materials import LABEL_COLOURS
from .scenes import Shot, check_style, ground_truth_of, intrinsics, make_scene, shoot
from .tree import SYNTH_DATE, check_out_folder, scene_seed, write_fast_depth, write_fast_image

__all__ = [
    "BASELINE",
    "EARTH_RADIUS",
    "FRAME_RATE",
    "ORIGIN_LAT_LON",
    "STEP",
    "STREET_GAP",
    "DriveFrame",
    "DriveManifest",
    "drive_name",
    "make_drive",
    "oxts_packet",
    "oxts_pose",
    "write_synthetic_drives",
]

#: KITTI's rectified stereo baseline, camera 02 -> camera 03 (metres; camera 03 is to the right).
BASELINE = 0.54
#: Frames per second (KITTI raw: 10 Hz).
FRAME_RATE = 10.0
#: Metres driven per frame (10 m/s).
STEP = 1.0
#: Where every synthetic drive starts (degrees; near KITTI's Karlsruhe).
ORIGIN_LAT_LON = (49.0, 8.4)
#: The Earth radius of KITTI's Mercator poses (metres).
EARTH_RADIUS = 6378137.0
#: How far apart (metres along the OXTS road) the streets of one drive folder are.
STREET_GAP = 1000.0
_DRIVE_BASE = 3000  # drive numbers: clear of the depth-completion trees' (0, 1000, 2000)


@dataclass
class DriveFrame:
    """One frame of a drive: the stereo pair, the LiDAR sweep, camera 02's ground truth and where the car is."""

    left: Shot  # camera 02
    right: Shot  # camera 03
    scan: LidarScan
    points: np.ndarray  # (N, 4) float32 the sweep as KITTI stores it: x, y, z (LiDAR frame, metres), reflectance
    gt: np.ndarray  # (H, W) float64 exact depth of camera 02 at ~16 % of the pixels (0 elsewhere)
    forward: float  # metres driven since the first frame


def drive_name(index: int) -> str:
    """The folder name of synthetic drive ``index``: ``2000_01_01_drive_NNNN_sync``."""
    return f"{SYNTH_DATE}_drive_{_DRIVE_BASE + index:04d}_sync"


def make_drive(
    frames: int,
    size: tuple[int, int],
    seed: int,
    style: str = "realistic",
    domain: str | Domain = "source",
    step: float = STEP,
) -> Iterator[DriveFrame]:
    """The ``frames`` frames of the drive of scene ``seed`` (see the module doc), one at a time.

    Raises:
        InputError: unknown ``style`` or ``domain`` (when the first frame is asked for).
    """
    check_style(style)
    dom = get_domain(domain)
    height, width = size
    K = intrinsics(height, width, True, dom)
    scene = make_scene(np.random.default_rng(seed), style, dom)
    for k in range(frames):
        rng = np.random.default_rng([seed, k])
        forward = k * step
        left_pose = Pose.of_camera(dom, forward)
        left = shoot(scene, K, size, left_pose, rng)
        right = shoot(scene, K, size, Pose.of_camera(dom, forward, right=BASELINE), rng)
        scan = simulate_lidar(
            height,
            width,
            K,
            scene.boxes,
            rng,
            scene.dressing is not None,
            dom,
            poses=(Pose.of_lidar(dom, forward), left_pose),
        )
        points = np.hstack([scan.points, _reflectance(scan, scene.boxes)[:, None]])
        yield DriveFrame(left, right, scan, points, ground_truth_of(left.depth, K, rng, dom), forward)


def _mercator_scale() -> float:
    return float(np.cos(np.deg2rad(ORIGIN_LAT_LON[0])))


def oxts_packet(forward: float, speed: float) -> list[float]:
    """The 30 OXTS fields of the car ``forward`` metres east of :data:`ORIGIN_LAT_LON` driving east at ``speed``
    m/s, level (lat, lon, alt, roll, pitch, yaw, vn, ve, vf, vl, vu, ax..au, wx..wu, accuracies, modes)."""
    lat, lon0 = ORIGIN_LAT_LON
    lon = lon0 + np.rad2deg(forward / (EARTH_RADIUS * _mercator_scale()))
    motion = [0.0, speed, speed, 0.0, 0.0]  # vn, ve, vf, vl, vu
    return [lat, lon, 100.0, 0.0, 0.0, 0.0, *motion, *[0.0] * 12, 0.02, 0.01, 4, 10, 5, 5, 6]


def oxts_pose(packet: list[float] | np.ndarray, scale: float | None = None) -> np.ndarray:
    """(4, 4) IMU pose (x forward, y left, z up) in KITTI's Mercator frame (east, north, up) of one OXTS packet:
    the devkit's ``convertOxtsToPose`` with Mercator ``scale`` (default: that of :data:`ORIGIN_LAT_LON`)."""
    lat, lon, alt, roll, pitch, yaw = (float(v) for v in packet[:6])
    s = _mercator_scale() if scale is None else scale
    t = [s * np.deg2rad(lon) * EARTH_RADIUS, s * EARTH_RADIUS * np.log(np.tan(np.deg2rad(90 + lat) / 2)), alt]

    def rot(axis: int, a: float) -> np.ndarray:
        c, n = np.cos(a), np.sin(a)
        i, j = [k for k in range(3) if k != axis]
        R = np.eye(3)
        R[i, i], R[i, j], R[j, i], R[j, j] = c, -n, n, c
        return R if axis != 1 else R.T  # rotation about y: x -> -z for a positive angle

    pose: np.ndarray = make_T(rot(2, yaw) @ rot(1, pitch) @ rot(0, roll), np.array(t))
    return pose


def _imu_to_velo(domain: Domain) -> np.ndarray:
    """(4, 4) IMU -> LiDAR: the IMU is level at the LiDAR's position, the LiDAR pitched down ``lidar_pitch``."""
    a = np.deg2rad(domain.lidar_pitch)
    R_imu_velo = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    T: np.ndarray = invert_T(make_T(R_imu_velo, np.zeros(3)))
    return T


def _numbers(values: npt.ArrayLike) -> str:
    return " ".join(f"{v:.12e}" for v in np.asarray(values, float).ravel())


def _write_calibration(
    date_dir: Path, K: np.ndarray, size: tuple[int, int], T_cam_lidar: np.ndarray, domain: Domain
) -> None:
    """The date folder's KITTI calibration: cameras 00 and 02 at the left camera, 01 and 03 at the right."""
    height, width = size
    rows = ["calib_time: 01-Jan-2000 00:00:00", "corner_dist: 9.950000e-02"]
    for cam, dx in (("00", 0.0), ("01", -BASELINE), ("02", 0.0), ("03", -BASELINE)):
        P = np.hstack([K, K @ np.array([[dx], [0.0], [0.0]])])
        rows += [
            f"S_{cam}: {width} {height}",
            f"K_{cam}: {_numbers(K)}",
            f"D_{cam}: 0 0 0 0 0",
            f"R_{cam}: {_numbers(np.eye(3))}",
            f"T_{cam}: {_numbers([dx, 0.0, 0.0])}",
            f"S_rect_{cam}: {width} {height}",
            f"R_rect_{cam}: {_numbers(np.eye(3))}",
            f"P_rect_{cam}: {_numbers(P)}",
        ]
    date_dir.mkdir(parents=True, exist_ok=True)
    (date_dir / "calib_cam_to_cam.txt").write_text("\n".join(rows) + "\n")
    velo = [
        "calib_time: 01-Jan-2000 00:00:00",
        f"R: {_numbers(T_cam_lidar[:3, :3])}",
        f"T: {_numbers(T_cam_lidar[:3, 3])}",
        "delta_f: 0 0",
        "delta_c: 0 0",
    ]
    (date_dir / "calib_velo_to_cam.txt").write_text("\n".join(velo) + "\n")
    imu = _imu_to_velo(domain)
    (date_dir / "calib_imu_to_velo.txt").write_text(
        f"calib_time: 01-Jan-2000 00:00:00\nR: {_numbers(imu[:3, :3])}\nT: {_numbers(imu[:3, 3])}\n"
    )


def _reflectance(scan: LidarScan, boxes: list[Box]) -> np.ndarray:
    """(N,) float32 reflectance of each return: the surface's mean albedo (road grey for the ground), 0..1."""
    albedo = np.array([b.albedo.mean() for b in boxes] + [86.7]) / 255.0  # index -1: the ground
    hit = scan.hit if scan.hit is not None else np.full(len(scan.points), -1)
    out: np.ndarray = np.clip(albedo[hit], 0.0, 1.0).astype(np.float32)
    return out


def _stamp(k: int) -> str:
    seconds = 12 * 3600 + k / FRAME_RATE
    return f"2000-01-01 {int(seconds // 3600):02d}:{int(seconds // 60 % 60):02d}:{seconds % 60:012.9f}"


class DriveManifest(TypedDict):
    """``drives.json``: how the drives were generated and each drive's scene seed."""

    generator: str
    style: str
    domain: str
    seed: int
    size: list[int]
    frames: int
    drives: list[dict[str, object]]


def _write_frame(out: Path, drive: str, k: int, fr: DriveFrame, offset: float = 0.0) -> None:
    """One frame (number ``k``, ``offset`` metres further along the OXTS road): the raw drive's files and the
    depth-completion files beside them."""
    from semattnet.data.io import quantize_depth

    name = f"{k:010d}"
    raw = out / "kitti_raw" / SYNTH_DATE / drive
    write_fast_image(layout.raw_image_path(out / "kitti_raw", drive, "02", name), fr.left.rgb)
    write_fast_image(layout.raw_image_path(out / "kitti_raw", drive, "03", name), fr.right.rgb)
    scan = raw / "velodyne_points" / "data" / f"{name}.bin"
    scan.parent.mkdir(parents=True, exist_ok=True)
    fr.points.astype("<f4").tofile(scan)
    oxts = raw / "oxts" / "data" / f"{name}.txt"
    oxts.parent.mkdir(parents=True, exist_ok=True)
    oxts.write_text(" ".join(f"{v:.14g}" for v in oxts_packet(offset + fr.forward, STEP * FRAME_RATE)) + "\n")
    write_fast_depth(layout.velodyne_path(out, "train", drive, "02", name), quantize_depth(fr.scan.sparse))
    write_fast_depth(layout.groundtruth_path(out, "train", drive, "02", name), quantize_depth(fr.gt))
    write_fast_image(layout.semantic_path(out / "semantic", drive, "02", name), LABEL_COLOURS[fr.left.labels])


def _write_timestamps(raw: Path, frames: int) -> None:
    stamps = "".join(_stamp(k) + "\n" for k in range(frames))
    for sub in ("image_02", "image_03", "velodyne_points", "oxts"):
        (raw / sub / "timestamps.txt").write_text(stamps)


def write_synthetic_drives(
    out: str | os.PathLike[str],
    drives: int = 1,
    frames: int = 10,
    size: tuple[int, int] = (96, 320),
    seed: int = 0,
    style: str = "realistic",
    domain: str | Domain = "source",
    overwrite: bool = False,
    streets: int = 1,
) -> DriveManifest:
    """Write ``drives`` drives of ``frames`` frames each (see the module doc) under ``out``: the raw drives in
    ``out/kitti_raw/DATE/``, the depth-completion ``train`` split and semantic maps beside them, and the manifest
    ``out/drives.json``. Drive ``i`` is the scene of seed ``scene_seed(seed, "drive", i)`` whatever ``drives``.

    ``streets`` > 1: each drive folder holds that many streets (``frames`` frames each) one after another, as a
    recording that drives through several places: street ``j`` of drive ``i`` is the scene of seed
    ``scene_seed(seed, "drive", i * streets + j)``, its frames numbered from ``j * (frames + 1)`` (one number
    left out between streets, so no reader takes the last frame of a street and the first of the next for
    neighbours) and its OXTS positions :data:`STREET_GAP` further along the road.

    Raises:
        FileExistsError: ``out`` holds files and ``overwrite`` is not set.
        OutputError: ``overwrite`` and ``out`` holds files but no tree of ours.
        InputError: unknown ``style`` or ``domain``.
    """
    check_style(style)
    dom = get_domain(domain)
    out = Path(out)
    check_out_folder(out, overwrite)
    mark_tree(out, "synth-drives", False, resume=f"write the drives into {out} again with overwrite=True")
    height, width = size
    K = intrinsics(height, width, True, dom)
    T_cam_lidar = lidar_to_camera(Pose.of_lidar(dom), Pose.of_camera(dom))  # the same in every frame
    _write_calibration(out / "kitti_raw" / SYNTH_DATE, K, size, T_cam_lidar, dom)
    entries: list[dict[str, object]] = []
    for d in range(drives):
        name, seeds = drive_name(d), [scene_seed(seed, "drive", d * streets + j) for j in range(streets)]
        for j, street_seed in enumerate(seeds):
            for k, fr in enumerate(make_drive(frames, size, street_seed, style, dom)):
                _write_frame(out, name, j * (frames + 1) + k, fr, j * STREET_GAP)
        _write_timestamps(out / "kitti_raw" / SYNTH_DATE / name, streets * (frames + 1) - 1)
        entries.append({"drive": name, "seeds": seeds, "frames": streets * frames})
    manifest: DriveManifest = {
        "generator": "semattnet.synthetic.drive",
        "style": style,
        "domain": dom.name,
        "seed": seed,
        "size": [height, width],
        "frames": frames,
        "drives": entries,
    }
    (out / "drives.json").write_text(json.dumps(manifest, indent=1))
    mark_tree(out, "synth-drives", True)
    return manifest
