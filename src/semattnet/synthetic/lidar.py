"""A simulated spinning LiDAR, and the sparse depth map its returns give in the camera.

In the source domain (:mod:`.domain`) it has 64 beams and sits 0.27 m behind and 0.08 m above the camera
(:data:`T_CAM_LIDAR`; so, as in KITTI, it sees a little behind foreground edges); other domains set the
beams, the field of view, the mounting and the pitch. The LiDAR frame has KITTI's Velodyne axes (x forward,
y left, z up). Rays are cast from the sensor, 2 cm range noise is added, and the returns are projected into
the camera by :func:`semattnet.geometry.project_points` (its pixel convention and z-buffer): ~5 % of pixels valid.
The realistic style's sensor effects (dark paint, gloss, glass, weak echoes) are :func:`sensor_effects`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semattnet.geometry.projection import project_points
from semattnet.geometry.transforms import make_T

from .domain import SOURCE, Domain, Pose
from .layout import Box
from .materials import MATERIAL_IDS, surfaces
from .raycast import cast

__all__ = [
    "LIDAR_ORIGIN",
    "MAX_RANGE",
    "MIN_DEPTH",
    "R_CAM_LIDAR",
    "T_CAM_LIDAR",
    "LidarScan",
    "lidar_to_camera",
    "sensor_effects",
    "simulate_lidar",
]

#: The LiDAR's position in the camera frame (x right, y down, z forward), metres.
LIDAR_ORIGIN = np.array([0.0, -0.08, -0.27])
#: Camera <- LiDAR rotation: LiDAR axes x forward, y left, z up (KITTI's Velodyne), camera x right, y down, z forward.
R_CAM_LIDAR = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
#: (4, 4) LiDAR -> camera transform (``p_cam = T_CAM_LIDAR @ p_lidar``).
T_CAM_LIDAR = make_T(R_CAM_LIDAR, LIDAR_ORIGIN)
#: Longest range the LiDAR returns, metres.
MAX_RANGE = 80.0
#: Returns closer to the camera than this (camera depth, metres) are not handed over.
MIN_DEPTH = 0.5

_P_DARK_RETURN = 0.15  # dark paint: most beams come back too weak
_P_GLOSSY_MIRROR, _P_GLOSSY_DROP = 0.35, 0.15  # glossy paint: mirrored beam (range too long) or none
_P_CAR_GLASS_THROUGH = 0.7  # car windows: the beam returns from the next surface behind, else nothing
_P_WINDOW_INTERIOR = 0.15  # building windows: a return from 2-10 m inside the room, else nothing


@dataclass
class LidarScan:
    """One sweep: the returns and the sparse depth map they give in the camera."""

    points: np.ndarray  # (N, 3) float32 returns in the LiDAR frame (metres), range noise included
    sparse: np.ndarray  # (H, W) float32 camera depth, 0 = no point: project_points(points, K, T_cam_lidar, (W, H))
    stats: dict[str, int] = field(default_factory=dict)  # what sensor_effects did (realistic style; else empty)
    hit: np.ndarray | None = None  # (N,) the box index each return came from (-1: the ground)
    T_cam_lidar: np.ndarray = field(default_factory=lambda: T_CAM_LIDAR.copy())  # (4, 4) LiDAR -> camera


def _beams(height: int, width: int, K: np.ndarray, rng: np.random.Generator, domain: Domain = SOURCE) -> np.ndarray:
    """(N, 3) unit beam directions in the LiDAR's camera-like axes: ``domain``'s beams over the camera's field."""
    elevation = np.deg2rad(np.linspace(*domain.elevation, domain.n_beams(height)))
    # ~0.46 points per image column per beam: ~5 % valid pixels, as KITTI (4-6 %).
    n_az = max(8, round(domain.points_per_column * width))
    half_fov = np.arctan(width / 2 / K[0, 0]) * 1.05
    az = np.linspace(-half_fov, half_fov, n_az) + rng.uniform(0, 2 * half_fov / n_az)
    el, a = np.meshgrid(elevation, az, indexing="ij")
    return np.stack((np.cos(el) * np.sin(a), -np.sin(el), np.cos(el) * np.cos(a)), axis=-1).reshape(-1, 3)


def lidar_to_camera(lidar: Pose, camera: Pose) -> np.ndarray:
    """(4, 4) LiDAR (Velodyne axes) -> camera transform of two poses in the street frame."""
    R = camera.R.T @ lidar.R @ R_CAM_LIDAR
    T: np.ndarray = make_T(R, camera.R.T @ (lidar.position - camera.position))
    return T


def simulate_lidar(
    height: int,
    width: int,
    K: np.ndarray,
    boxes: list[Box],
    rng: np.random.Generator,
    realistic: bool = False,
    domain: Domain = SOURCE,
    poses: tuple[Pose, Pose] | None = None,
) -> LidarScan:
    """Cast the beams, apply the sensor effects (``realistic``) and range noise, project into the camera.

    ``poses``: the LiDAR's and the camera's in the street frame (default: ``domain``'s at the street's start).
    """
    lidar, camera = poses if poses is not None else (Pose.of_lidar(domain), Pose.of_camera(domain))
    local = _beams(height, width, K, rng, domain)
    dirs = local if domain.lidar_pitch == 0.0 else local @ lidar.R.T  # street axes
    t, idx, axis = cast(lidar.position, dirs, boxes)
    stats: dict[str, int] = {}
    if realistic:
        t, stats = sensor_effects(dirs, t, idx, axis, boxes, rng, lidar.position)
    ok = np.isfinite(t) & (t < MAX_RANGE)
    t = t[ok] + rng.normal(0.0, 0.02, ok.sum())  # range noise
    rel = local[ok] * t[:, None]  # the LiDAR's camera-like axes, from the sensor
    T_cam_lidar = lidar_to_camera(lidar, camera)
    depth = rel @ (camera.R.T @ lidar.R)[2] + T_cam_lidar[2, 3]
    keep = depth > MIN_DEPTH  # in front of the camera
    rel, hit = rel[keep], idx[ok][keep]
    points = (rel @ R_CAM_LIDAR).astype(np.float32)  # R^T applied to each row: camera axes -> LiDAR axes
    if len(points) == 0:
        return LidarScan(points.reshape(0, 3), np.zeros((height, width), np.float32), stats, hit, T_cam_lidar)
    sparse = project_points(points, K, T_cam_lidar, (width, height), name="synthetic LiDAR")
    return LidarScan(points, sparse, stats, hit, T_cam_lidar)


def _reflected_range(points: np.ndarray, dirs: np.ndarray, axis: np.ndarray, boxes: list[Box]) -> np.ndarray:
    """Range from a mirroring box face (``axis``) along the reflected ray to the next surface (inf: none)."""
    r = dirs.copy()
    r[np.arange(len(r)), axis] *= -1
    t, _, _ = cast(points + 1e-4 * r, r, boxes)
    return t


def _through_range(dirs: np.ndarray, idx: np.ndarray, boxes: list[Box], origin: np.ndarray) -> np.ndarray:
    """Range from the LiDAR at ``origin`` to the next surface behind the car each ray hit (cast without that car)."""
    group = np.array([b.group for b in boxes])[idx]
    t = np.full(len(dirs), np.inf)
    for g in np.unique(group):
        sel = group == g
        t[sel], _, _ = cast(origin, dirs[sel], [b for b in boxes if b.group != g])
    return t


def sensor_effects(
    dirs: np.ndarray,
    t: np.ndarray,
    idx: np.ndarray,
    axis: np.ndarray,
    boxes: list[Box],
    rng: np.random.Generator,
    origin: np.ndarray = LIDAR_ORIGIN,
) -> tuple[np.ndarray, dict[str, int]]:
    """Realistic LiDAR returns: ranges (inf: none) after paint, glass, range and grazing effects, and counts.

    ``dirs``: unit beams in the street frame from the sensor at ``origin``."""
    n = len(t)
    hit = np.isfinite(t) & (t < MAX_RANGE)
    points = origin + dirs * np.where(hit, t, 0.0)[:, None]
    material, _, _ = surfaces(points, idx, axis, boxes)
    is_car = np.array([b.cls == "car" for b in boxes] or [False])[np.where(idx >= 0, idx, 0)] & (idx >= 0)
    u, v, inside = rng.random(n), rng.random(n), rng.uniform(2.0, 10.0, n)
    dark, glossy = hit & (material == MATERIAL_IDS["dark"]), hit & (material == MATERIAL_IDS["glossy"])
    car_glass = hit & (material == MATERIAL_IDS["glass"]) & is_car
    window = hit & (material == MATERIAL_IDS["glass"]) & ~is_car
    mirror, through = glossy & (v >= 1 - _P_GLOSSY_MIRROR), car_glass & (v < _P_CAR_GLASS_THROUGH)
    interior = window & (v < _P_WINDOW_INTERIOR)
    out = np.where(hit, t, np.inf)
    out[mirror] = t[mirror] + _reflected_range(points[mirror], dirs[mirror], axis[mirror], boxes)
    out[through] = _through_range(dirs[through], idx[through], boxes, origin)
    out[interior] += inside[interior]
    dropped = {
        "dark": dark & (v >= _P_DARK_RETURN),
        "glossy": glossy & (v < _P_GLOSSY_DROP),
        "glass": (car_glass & ~through) | (window & ~interior),
    }
    # Weak echoes: fewer returns at grazing incidence (cosine to the normal below ~0.12) and beyond 25 m.
    cos_in = np.abs(dirs[np.arange(n), np.where(idx >= 0, axis, 1)])
    rng_m = np.where(np.isfinite(out), out, 0.0)
    p = np.clip(0.25 + 6.0 * cos_in, 0, 1) * np.clip(1 - np.maximum(0, rng_m - 25) / 70, 0.2, 1)
    gone = dropped["dark"] | dropped["glossy"] | dropped["glass"]
    dropped["range_grazing"] = hit & ~gone & np.isfinite(out) & (u >= p)
    out[gone | dropped["range_grazing"]] = np.inf
    kept = np.isfinite(out) & (out < MAX_RANGE)
    stats = {
        "rays": n,
        "first_surface_hits": int(hit.sum()),
        "returns": int(kept.sum()),
        **{f"dropped_{k}": int(m.sum()) for k, m in dropped.items()},
        "wrong_glossy": int((mirror & kept).sum()),
        "wrong_car_glass": int((through & kept).sum()),
        "wrong_window": int((interior & kept).sum()),
    }
    return out, stats
