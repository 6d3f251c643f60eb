"""Exact ray casting against the scene's boxes and ground plane, and the camera's view of the scene.

Camera rays go through pixel centres, which sit at integer coordinates (the convention of
:mod:`semattnet.geometry.projection`): the ray of pixel (row v, column u) is ``((u - cx) / fx, (v - cy) / fy, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .domain import Pose
from .layout import CAM_HEIGHT, Box

__all__ = ["RayView", "camera_view", "cast", "cast_camera", "pixel_rays"]


def cast(origin: np.ndarray, dirs: np.ndarray, boxes: list[Box]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest hit along each ray: distance t (inf on a miss), box index (-1 ground, -2 sky), face axis.

    ``origin`` is one point (3,) or one per ray (N, 3); ``dirs`` (N, 3); t in units of ``|dirs|``.
    """
    n = dirs.shape[0]
    t_best = np.full(n, np.inf)
    idx = np.full(n, -2, dtype=np.int64)
    axis = np.full(n, 1, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = (CAM_HEIGHT - origin[..., 1]) / dirs[:, 1]
    ground = (dirs[:, 1] > 1e-9) & (t_ground > 0)
    t_best[ground] = t_ground[ground]
    idx[ground] = -1
    inv = [1.0 / np.where(np.abs(dirs[:, k]) < 1e-12, 1e-12, dirs[:, k]) for k in range(3)]
    for b, box in enumerate(boxes):  # slab test, one axis at a time (no reductions over a tiny axis)
        near, far = [], []
        for k in range(3):
            t1, t2 = (box.lo[k] - origin[..., k]) * inv[k], (box.hi[k] - origin[..., k]) * inv[k]
            near.append(np.minimum(t1, t2))
            far.append(np.maximum(t1, t2))
        tmin = np.maximum(np.maximum(near[0], near[1]), near[2])
        tmax = np.minimum(np.minimum(far[0], far[1]), far[2])
        hit = (tmax >= tmin) & (tmin > 1e-6) & (tmin < t_best)
        if hit.any():
            t_best[hit] = tmin[hit]
            idx[hit] = b
            nx, ny, nz = near[0][hit], near[1][hit], near[2][hit]
            axis[hit] = np.where((nx >= ny) & (nx >= nz), 0, np.where(ny >= nz, 1, 2))
    return t_best, idx, axis


def pixel_rays(K: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W, 3) camera rays (z = 1) through the pixel centres, at integer (u, v)."""
    v, u = np.mgrid[0:height, 0:width]
    return np.stack(((u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((height, width))), -1)


def _screen_window(K: np.ndarray, height: int, width: int, box: Box, pose: Pose | None) -> tuple[slice, slice] | None:
    """Rows and columns whose pixel centres may see ``box`` (a conservative screen rectangle), or None.

    ``pose``: the camera's (None: the street frame itself); a box partly behind a moved camera gets the whole image.
    """
    lo, hi = box.lo.copy(), box.hi.copy()
    if pose is None:
        lo[2] = max(lo[2], 0.1)  # the part in front of the camera
        if hi[2] <= lo[2]:
            return None
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    if pose is not None:
        corners = (corners - pose.position) @ pose.R  # street -> camera: R^T (p - position), row by row
        if corners[:, 2].max() <= 0.1:
            return None
        if corners[:, 2].min() <= 0.1:
            return slice(0, height), slice(0, width)
    pu = K[0, 0] * corners[:, 0] / corners[:, 2] + K[0, 2]
    pv = K[1, 1] * corners[:, 1] / corners[:, 2] + K[1, 2]
    u0, u1 = max(0, int(np.floor(pu.min()))), min(width, int(np.ceil(pu.max())) + 1)
    v0, v1 = max(0, int(np.floor(pv.min()))), min(height, int(np.ceil(pv.max())) + 1)
    if u0 >= u1 or v0 >= v1:
        return None
    return slice(v0, v1), slice(u0, u1)


def cast_camera(
    K: np.ndarray, height: int, width: int, boxes: list[Box], pose: Pose | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`cast` for the camera's pixel rays (:func:`pixel_rays`), testing each box only inside its
    screen rectangle. Returns flattened (row-major) rays (N, 3, street axes), t, box index and face axis.

    ``pose``: the camera's pose in the street frame (None or the identity: the street frame's own camera).
    """
    pose = None if pose is None or pose.identity else pose
    dirs = pixel_rays(K, height, width) if pose is None else pixel_rays(K, height, width) @ pose.R.T
    origin = np.zeros(3) if pose is None else pose.position
    t_best, idx, axis = (a.reshape(height, width) for a in cast(origin, dirs.reshape(-1, 3), []))
    for b, box in enumerate(boxes):
        win = _screen_window(K, height, width, box, pose)
        if win is None:
            continue
        t, _, ax = cast(origin, dirs[win].reshape(-1, 3), [box])
        t = t.reshape(t_best[win].shape)
        hit = t < t_best[win]
        t_best[win] = np.where(hit, t, t_best[win])
        idx[win] = np.where(hit, b, idx[win])
        axis[win] = np.where(hit, ax.reshape(t.shape), axis[win])
    return dirs.reshape(-1, 3), t_best.reshape(-1), idx.reshape(-1), axis.reshape(-1)


@dataclass
class RayView:
    """What the camera sees, per pixel (flattened row-major): ray, what it hits and where."""

    height: int
    width: int
    dirs: np.ndarray  # (N, 3) pixel rays (street axes; z = 1 in the camera's)
    idx: np.ndarray  # (N,) box index hit, -1 ground, -2 sky (or beyond 150 m)
    axis: np.ndarray  # (N,) axis of the box face hit
    far: np.ndarray  # (N,) sky or beyond 150 m: no surface
    points: np.ndarray  # (N, 3) surface points in the street frame (the camera's position where far)
    on_box: np.ndarray  # (N,) the ray hits a box
    ground: np.ndarray  # (N,) the ray hits the ground
    depth: np.ndarray  # (N,) depth in the camera (z of the camera frame), 0 where far


def camera_view(K: np.ndarray, height: int, width: int, boxes: list[Box], pose: Pose | None = None) -> RayView:
    """Cast the camera's rays (from ``pose``, see :func:`cast_camera`); hits beyond 150 m count as sky."""
    dirs, t, idx, axis = cast_camera(K, height, width, boxes, pose)
    far = ~np.isfinite(t) | (t > 150)  # t is the depth: the rays have z = 1 in the camera
    idx[far] = -2
    depth = np.where(far, 0.0, t)
    points = dirs * depth[:, None]
    if pose is not None and not pose.identity:
        points += pose.position
    return RayView(height, width, dirs, idx, axis, far, points, idx >= 0, idx == -1, depth)
