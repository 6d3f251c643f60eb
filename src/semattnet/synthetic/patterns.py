"""Sparse depth patterns of the synthetic world, drawn from an exact depth map (H, W) (metres, 0 = none).

``"lidar"`` (:func:`lidar_pattern`): a spinning LiDAR of 8-128 beams (random elevation span, azimuth step, pitch and
mount offset from the camera), its beams cast against the scene's boxes from where it sits, so background it sees
past a foreground edge lands beside that edge in the camera (KITTI's bleed-through); 0-30 % dropouts, range noise.
``"points"`` (:func:`points_pattern`): 50-5000 random pixels of the exact depth (the NYU protocol's 500 in 30 % of
draws), up to 1 % noise. ``"depthcam"`` (:func:`depthcam_pattern`): a depth camera: dense, with holes at depth edges,
in the projector's shadow beside them, in random blobs, beyond a 4-10 m range, on a share of dark or glossy surfaces;
noise growing with depth squared; subsampled by a factor 1-4 in 60 % of draws.

Each returns ``(sparse, info)``: (H, W) float32 metres (0 = missing) and a dict of what it drew.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from semattnet._errors import InputError

from .domain import Domain, Pose, pitch_down
from .layout import Box
from .lidar import simulate_lidar

__all__ = [
    "PATTERNS",
    "LidarRig",
    "apply_pattern",
    "depth_edges",
    "depthcam_pattern",
    "lidar_pattern",
    "points_pattern",
    "random_rig",
]

#: The sparse patterns, by name.
PATTERNS: tuple[str, ...] = ("lidar", "points", "depthcam")
_MAX_RAYS = 48_000  # beams x azimuth steps cast per sweep (the azimuth step widens beyond)
Info = dict[str, Any]
#: A pattern's own settings by name (:data:`semattnet.synthetic.world.PATTERN_OPTIONS`), as keyword arguments.
Options = Info


class LidarRig(Domain):
    """A :class:`~.domain.Domain` whose LiDAR has all its beams at any image size (no scaling with the rows)."""

    def n_beams(self, height: int) -> int:
        """All the beams."""
        return self.beams


def _heading(camera: Pose) -> tuple[float, float]:
    """The camera's yaw (deg from +z towards +x) and pitch (deg down) in the street frame."""
    forward = camera.R[:, 2]
    return float(np.rad2deg(np.arctan2(forward[0], forward[2]))), float(np.rad2deg(np.arcsin(forward[1])))


def _yaw(degrees: float) -> np.ndarray:
    """(3, 3) rotation about the vertical (y) axis, from +z towards +x."""
    c, s = np.cos(np.deg2rad(degrees)), np.sin(np.deg2rad(degrees))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def random_rig(rng: np.random.Generator, camera_pitch: float, hfov: float, width: int, indoor: bool) -> LidarRig:
    """A random LiDAR: 8-128 beams over a random elevation span (top 2..22 deg, bottom -45..-15 deg), a 0.08-0.4 deg
    azimuth step, pitched like the camera (``camera_pitch``, deg down) +-4 deg, mounted up to 0.5 m (indoors 0.3 m)
    to either side, 0.6 m (0.35 m) above to 0.2 m (0.1 m) below, 0.8 m (0.3 m) behind to 0.4 m (0.15 m) ahead of the
    camera (``width`` pixels over ``hfov`` degrees)."""
    beams = round(float(2 ** rng.uniform(3, 7)))
    elevation = (float(rng.uniform(2, 22)), float(rng.uniform(-45, -15)))
    step = rng.uniform(0.08, 0.4)
    low, high = ([-0.3, -0.35, -0.3], [0.3, 0.1, 0.15]) if indoor else ([-0.5, -0.6, -0.8], [0.5, 0.2, 0.4])
    x, y, z = (float(v) for v in rng.uniform(low, high))
    pitch = float(camera_pitch + rng.uniform(-4, 4))
    per_column = float(hfov / (step * width))
    return LidarRig("world", beams, elevation, per_column, (x, y, z), pitch)


def _in_view(rig: LidarRig, K: np.ndarray, height: int, width: int, camera_pitch: float) -> LidarRig | None:
    """The rig's beams that can reach the camera's rows (with a margin for the mount's parallax at 1 m), within
    :data:`_MAX_RAYS` rays; None: no beam does."""
    el = np.linspace(*rig.elevation, rig.beams)
    up, down = np.rad2deg(np.arctan(K[1, 2] / K[1, 1])), np.rad2deg(np.arctan((height - 1 - K[1, 2]) / K[1, 1]))
    margin = 3.0 + np.rad2deg(np.arctan(np.linalg.norm(rig.lidar_offset)))
    shift = rig.lidar_pitch - camera_pitch
    seen = np.flatnonzero((el >= -down + shift - margin) & (el <= up + shift + margin))
    if seen.size == 0:
        return None
    k0, k1 = int(seen[0]), int(seen[-1])
    while k1 - k0 < 3:  # a Domain has 4 beams or more
        k0, k1 = (k0 - 1, k1) if k0 > 0 else (k0, k1 + 1)
    n = k1 - k0 + 1
    per_column = min(rig.points_per_column, _MAX_RAYS / (n * width))
    pitch = rig.lidar_pitch or 1e-9  # not 0: simulate_lidar turns the beams with the pose only when pitched
    return replace(
        rig, beams=n, elevation=(float(el[k0]), float(el[k1])), points_per_column=per_column, lidar_pitch=pitch
    )


def lidar_pattern(
    depth: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    boxes: list[Box],
    camera: Pose,
    rig: LidarRig | None = None,
    realistic: bool = False,
) -> tuple[np.ndarray, Info]:
    """A sweep of ``rig`` (random: :func:`random_rig`) cast against ``boxes`` (street frame, ``camera``'s pose), as
    the camera sees it (:func:`~.lidar.simulate_lidar`; ``realistic``: the realistic style's sensor effects), with
    0-30 % of the points dropped and 0-3 cm more noise (beyond the simulator's 2 cm range noise). ``depth`` gives
    the image size.

    The LiDAR turns with the camera (same yaw); ``rig.lidar_offset`` is its mount in the camera's level axes.
    """
    (height, width), (yaw, pitch) = depth.shape, _heading(camera)
    hfov = float(2 * np.rad2deg(np.arctan(width / 2 / K[0, 0])))
    rig = random_rig(rng, pitch, hfov, width, indoor=False) if rig is None else rig
    drop, noise = float(rng.uniform(0, 0.3)), float(rng.uniform(0, 0.03))
    info: Info = {"pattern": "lidar", "beams": rig.beams, "elevation": list(rig.elevation), "dropout": drop}
    info |= {"mount": list(rig.lidar_offset), "lidar_pitch": rig.lidar_pitch, "extra_noise": noise}
    info["azimuth_step"] = hfov / (rig.points_per_column * width)
    seen = _in_view(rig, K, height, width, pitch)
    if seen is None:
        return np.zeros((height, width), np.float32), info | {"beams_in_view": 0}
    R = _yaw(yaw)
    lidar = Pose(camera.position + R @ np.asarray(rig.lidar_offset), R @ pitch_down(seen.lidar_pitch))
    sparse = simulate_lidar(height, width, K, boxes, rng, realistic, seen, (lidar, camera)).sparse
    keep = (sparse > 0) & (rng.random(sparse.shape) >= drop)
    sparse = np.where(keep, np.maximum(sparse + rng.normal(0.0, max(noise, 1e-9), sparse.shape), 0.05), 0.0)
    return sparse.astype(np.float32), info | {"beams_in_view": seen.beams}


def points_pattern(
    depth: np.ndarray, K: np.ndarray, rng: np.random.Generator, count: int | None = None, noise: float | None = None
) -> tuple[np.ndarray, Info]:
    """``count`` random pixels with a depth (or all of them, if fewer; None: 50-5000, log-uniform, or the NYU
    protocol's 500 in 30 % of draws), each with ``noise`` relative noise (None: 0-1 %, clipped at 3 sigma)."""
    if count is None:
        count = 500 if rng.random() < 0.3 else round(float(np.exp(rng.uniform(np.log(50), np.log(5000)))))
    noise = float(rng.uniform(0, 0.01)) if noise is None else noise
    valid = np.flatnonzero(depth.reshape(-1) > 0)
    pick = rng.choice(valid, size=min(count, valid.size), replace=False)
    sparse = np.zeros(depth.size, np.float32)
    sparse[pick] = depth.reshape(-1)[pick] * (1 + noise * np.clip(rng.standard_normal(pick.size), -3, 3))
    return sparse.reshape(depth.shape), {"pattern": "points", "count": count, "valid": int(pick.size), "noise": noise}


def depth_edges(depth: np.ndarray, jump: float = 0.05) -> np.ndarray:
    """(H, W) bool: pixels with a 4-neighbour, both with a depth, more than ``jump`` x the nearer depth (and 10 cm)
    away in depth: both sides of every depth edge."""
    edge = np.zeros(depth.shape, dtype=bool)
    for a, b in ((depth[1:], depth[:-1]), (depth[:, 1:], depth[:, :-1])):
        step = (a > 0) & (b > 0) & (np.abs(a - b) > np.maximum(0.1, jump * np.minimum(a, b)))
        if a.shape[0] < depth.shape[0]:
            edge[1:] |= step
            edge[:-1] |= step
        else:
            edge[:, 1:] |= step
            edge[:, :-1] |= step
    return edge


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """``mask`` grown by ``radius`` pixels (a square)."""
    out: np.ndarray = mask.copy()
    for _ in range(radius):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
        out = grown
    return out


def _projector_shadow(depth: np.ndarray, fx: float, baseline: float, side: int) -> np.ndarray:
    """(H, W) bool: background the projector, ``baseline`` metres to the right (``side`` 1) or left (-1) of the
    camera, cannot light: ``fx * baseline * (1 / z_near - 1 / z_far)`` pixels beside each vertical depth edge."""
    d = depth if side > 0 else depth[:, ::-1]
    left, right = d[:, :-1], d[:, 1:]
    edge = (left > 0) & (right > 0) & (left - right > np.maximum(0.1, 0.05 * right))  # far on the left
    with np.errstate(divide="ignore"):
        width = np.where(edge, np.ceil(fx * baseline * (1 / np.maximum(right, 1e-3) - 1 / np.maximum(left, 1e-3))), 0)
    width = np.minimum(width, 40).astype(int)
    shadow = np.zeros(d.shape, dtype=bool)
    for k in range(int(width.max(initial=0))):
        shadow[:, : d.shape[1] - 1 - k] |= width[:, k:] > k
    return shadow if side > 0 else shadow[:, ::-1]


def _blobs(shape: tuple[int, int], share: float, cell: int, rng: np.random.Generator) -> np.ndarray:
    """(H, W) bool: smooth random blobs covering about ``share`` of the image (noise on a ``cell``-pixel grid,
    bilinearly upsampled, thresholded)."""
    h, w = shape
    grid = rng.random((h // cell + 2, w // cell + 2))
    y, x = np.arange(h) / cell, np.arange(w) / cell
    i, j = y.astype(int), x.astype(int)
    fy, fx = (y - i)[:, None], (x - j)[None, :]
    top = grid[i][:, j] * (1 - fx) + grid[i][:, j + 1] * fx
    bottom = grid[i + 1][:, j] * (1 - fx) + grid[i + 1][:, j + 1] * fx
    field = top * (1 - fy) + bottom * fy
    blobs: np.ndarray = field > np.quantile(field, 1 - share) if share > 0 else np.zeros(shape, dtype=bool)
    return blobs


def _draw_depthcam(rng: np.random.Generator, max_range: float | None, factor: int | None) -> Info:
    """The depth camera's settings."""
    if factor is None:
        factor = 1 if rng.random() < 0.4 else int(rng.integers(2, 5))
    return {
        "pattern": "depthcam",
        "max_range": float(rng.uniform(4, 10)) if max_range is None else max_range,
        "min_range": float(rng.uniform(0.3, 0.5)),
        "edge_radius": int(rng.integers(0, 3)),
        "baseline": float(rng.uniform(0.03, 0.1)),
        "projector_side": int(rng.choice([-1, 1])),
        "blob_share": float(rng.uniform(0, 0.1)),
        "blob_cell": int(rng.integers(8, 33)),
        "dark_share": float(rng.uniform(0, 0.3)),
        "noise_k": float(rng.uniform(0.0005, 0.004)),
        "factor": factor,
    }


def depthcam_pattern(
    depth: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    surface: np.ndarray | None = None,
    absorbing: np.ndarray | None = None,
    max_range: float | None = None,
    factor: int | None = None,
) -> tuple[np.ndarray, Info]:
    """A depth camera's map: the exact depth with holes on both sides of every depth edge (grown by 0-2 pixels), in
    the projector's shadow, in random blobs (0-10 %), nearer than 0.3-0.5 m or beyond ``max_range`` (None: 4-10 m),
    on a 0-30 % share of the surfaces (``surface``: (H, W) ids, e.g. box indices; each chosen one loses 60-100 % of
    its pixels) and on 90 % of ``absorbing`` pixels (known dark, glossy or glass); noise ``k * depth ** 2`` (k
    0.0005-0.004); kept on a regular grid of every ``factor``-th row and column (None: 1, or 2-4 in 60 % of draws).
    """
    info = _draw_depthcam(rng, max_range, factor)
    hole = _dilate(depth_edges(depth), info["edge_radius"])
    hole |= _projector_shadow(depth, float(K[0, 0]), info["baseline"], info["projector_side"])
    hole |= _blobs((depth.shape[0], depth.shape[1]), info["blob_share"], info["blob_cell"], rng)
    hole |= (depth < info["min_range"]) | (depth > info["max_range"])
    if surface is not None:
        ids, inverse = np.unique(surface, return_inverse=True)
        rate = np.where(rng.random(ids.size) < info["dark_share"], rng.uniform(0.6, 1.0, ids.size), 0.0)
        hole |= rng.random(depth.shape) < rate[inverse.reshape(depth.shape)]
        info["dark_surfaces"] = int((rate > 0).sum())
    if absorbing is not None:
        hole |= absorbing & (rng.random(depth.shape) < 0.9)
    f = info["factor"]
    grid = np.zeros(depth.shape, dtype=bool)
    grid[int(rng.integers(f)) :: f, int(rng.integers(f)) :: f] = True
    noisy = depth + info["noise_k"] * depth**2 * rng.standard_normal(depth.shape)
    sparse = np.where(~hole & grid & (depth > 0), np.maximum(noisy, 0.05), 0.0).astype(np.float32)
    return sparse, info | {"valid": int((sparse > 0).sum())}


def apply_pattern(
    pattern: str,
    depth: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    boxes: list[Box] | None = None,
    camera: Pose | None = None,
    **options: Any,
) -> tuple[np.ndarray, Info]:
    """The ``pattern`` (one of :data:`PATTERNS`) of ``depth``; ``boxes`` and ``camera`` for the LiDAR; ``options``
    go to the pattern's function.

    Raises:
        InputError: an unknown pattern, or the LiDAR without ``boxes`` and ``camera``.
    """
    if pattern == "points":
        return points_pattern(depth, K, rng, **options)
    if pattern == "depthcam":
        return depthcam_pattern(depth, K, rng, **options)
    if pattern != "lidar":
        raise InputError(f"pattern: unknown sparse pattern {pattern!r}; expected one of {', '.join(PATTERNS)}")
    if boxes is None or camera is None:
        raise InputError("pattern 'lidar' needs the scene's boxes and the camera's pose")
    return lidar_pattern(depth, K, rng, boxes, camera, **options)
