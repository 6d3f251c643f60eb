"""Labels, colours and light of what the camera sees: Lambertian sunlight, shadows cast onto the road,
an optional overpass band, 6 % image noise and a sky gradient."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from .layout import CAM_HEIGHT, Box, road_half_width, window_corners
from .materials import CLASS_IDS
from .raycast import RayView

__all__ = [
    "albedo",
    "convex_hull",
    "ground_shadow",
    "labels",
    "overpass",
    "overpass_band",
    "render",
    "sun_direction",
    "sunlight",
]


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise, monotone chain) of 2-D points (N, 2)."""
    pts = sorted(map(tuple, points))
    if len(pts) <= 2:
        return np.array(pts)

    def half(seq: Iterable[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
        out: list[tuple[Any, ...]] = []
        for p in seq:
            while (
                len(out) >= 2
                and (out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])
                <= 0
            ):
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.array(lower[:-1] + upper[:-1])


def ground_shadow(xz: np.ndarray, boxes: list[Box], sun: np.ndarray) -> np.ndarray:
    """Which ground points (N, 2: x, z) lie in the shadow some box casts along ``sun``."""
    shadow = np.zeros(len(xz), dtype=bool)
    for box in boxes:
        corners = np.array(
            [[x, y, z] for x in (box.lo[0], box.hi[0]) for y in (box.lo[1], box.hi[1]) for z in (box.lo[2], box.hi[2])]
        )
        t = (CAM_HEIGHT - corners[:, 1]) / sun[1]  # slide each corner along the sun ray to the ground
        hull = convex_hull(corners[:, [0, 2]] + t[:, None] * sun[[0, 2]])
        lo, hi = hull.min(0), hull.max(0)
        cand = np.flatnonzero((xz[:, 0] >= lo[0]) & (xz[:, 0] <= hi[0]) & (xz[:, 1] >= lo[1]) & (xz[:, 1] <= hi[1]))
        if cand.size == 0 or len(hull) < 3:
            continue
        inside = np.ones(cand.size, dtype=bool)
        p = xz[cand]
        for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
            inside &= (b[0] - a[0]) * (p[:, 1] - a[1]) - (b[1] - a[1]) * (p[:, 0] - a[0]) >= 0
        shadow[cand[inside]] = True
    return shadow


def labels(view: RayView, boxes: list[Box]) -> np.ndarray:
    """(N,) class ids: boxes by class, the ground by its distance from the road's centre line."""
    out = np.full(view.height * view.width, CLASS_IDS["sky"], dtype=np.int64)
    box_cls = np.array([CLASS_IDS[b.cls] for b in boxes] or [0], dtype=np.int64)
    out[view.on_box] = box_cls[view.idx[view.on_box]]
    road_half = road_half_width(boxes)
    out[view.ground] = np.where(
        np.abs(view.points[view.ground, 0]) < road_half, CLASS_IDS["road"], CLASS_IDS["sidewalk"]
    )
    return out


def albedo(view: RayView, labels: np.ndarray, boxes: list[Box]) -> np.ndarray:
    """(N, 3) surface colours: box albedos, road with lane markings, sidewalk, facades with windows."""
    points, on_box = view.points, view.on_box
    out = np.zeros((view.height * view.width, 3))
    out[on_box] = np.array([b.albedo for b in boxes])[view.idx[on_box]]
    road = labels == CLASS_IDS["road"]
    out[road] = [85, 85, 90]
    out[labels == CLASS_IDS["sidewalk"]] = [150, 140, 135]
    lane = road & (np.abs(points[:, 0]) < 0.08) & (np.mod(points[:, 2], 6.0) < 3.0)
    out[lane] = [235, 235, 230]
    facade = on_box & (labels == CLASS_IDS["building"]) & (view.axis != 1)
    out[facade & window_corners(points)] *= 0.45  # windows
    return out


def sun_direction(
    rng: np.random.Generator, x: tuple[float, float] = (-0.6, 0.6), z: tuple[float, float] = (-0.3, 0.8)
) -> np.ndarray:
    """A random unit direction the sunlight travels (downwards: y = 1 before normalising, x and z drawn in ranges)."""
    sun = np.array([rng.uniform(*x), 1.0, rng.uniform(*z)])
    sun /= np.linalg.norm(sun)
    return sun


def sunlight(view: RayView, boxes: list[Box], sun: np.ndarray, exposure: float) -> np.ndarray:
    """(N,) light: ``exposure`` x (ambient + Lambertian sun), no sun where a box shades the ground."""
    normal = np.zeros((view.height * view.width, 3))
    normal[view.ground] = [0, -1, 0]
    on = np.flatnonzero(view.on_box)
    normal[on, view.axis[on]] = -np.sign(view.dirs[on, view.axis[on]])
    lit = np.clip(-(normal @ sun), 0.0, 1.0)
    in_shadow = np.zeros(view.height * view.width, dtype=bool)
    in_shadow[view.ground] = ground_shadow(view.points[view.ground][:, [0, 2]], boxes, sun)
    shade: np.ndarray = exposure * (0.45 + 0.75 * lit * ~in_shadow)
    return shade


def overpass_band(rng: np.random.Generator) -> tuple[float, float]:
    """A random band of the street (an overpass): its z range in the street frame."""
    z0 = rng.uniform(6, 18)
    return z0, z0 + rng.uniform(4, 9)


def overpass(view: RayView, light: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Shade the overpass ``band`` of the street (:func:`overpass_band`), whatever the surface: the new light."""
    z = view.points[:, 2]
    shaded: np.ndarray = np.where(~view.far & (z > band[0]) & (z < band[1]), light * 0.3, light)
    return shaded


def render(
    view: RayView, albedo: np.ndarray, light: np.ndarray, exposure: float, rng: np.random.Generator, noise: float = 0.06
) -> np.ndarray:
    """(H, W, 3) uint8 image: albedo x light x (1 + ``noise`` x a normal draw), and a vertical gradient for the sky."""
    h, w, far = view.height, view.width, view.far
    grain = 1.0 + noise * rng.standard_normal(h * w)
    rgb = albedo * (light * grain)[:, None]
    sky_v = np.mgrid[0:h, 0:w][0].reshape(-1)[far] / max(1, h)
    rgb[far] = np.stack((150 + 60 * sky_v, 185 + 40 * sky_v, 235 + 0 * sky_v), -1) * exposure
    return np.clip(rgb, 0, 255).astype(np.uint8).reshape(h, w, 3)
