"""Small procedural driving scenes with exact depth, for demos and tests.

A pinhole camera with KITTI-like intrinsics (scaled to the requested size) looks down a road
lined with sidewalks, building facades and parked cars (axis-aligned boxes), under a sky. Each
pixel's depth is found by ray casting; the RGB image is shaded per class with texture noise and
an optional cast shadow across the road; the semantic map uses the Cityscapes palette; the
sparse map samples the depth along 64 simulated LiDAR beams (~5 % of pixels) and the ground
truth keeps a denser random ~16 % of pixels, like KITTI's accumulated maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CITYSCAPES_PALETTE", "SyntheticFrame", "make_frame"]

#: Cityscapes trainId colours used by the generator (class name -> RGB).
CITYSCAPES_PALETTE = {
    "road": (128, 64, 128),
    "sidewalk": (244, 35, 232),
    "building": (70, 70, 70),
    "pole": (153, 153, 153),
    "vegetation": (107, 142, 35),
    "sky": (70, 130, 180),
    "car": (0, 0, 142),
}
_ALBEDO = {
    "road": (90, 90, 95),
    "sidewalk": (150, 140, 135),
    "building": (160, 120, 100),
    "pole": (120, 120, 120),
    "vegetation": (60, 110, 40),
    "sky": (170, 200, 235),
    "car": (40, 60, 150),
}
_CLASSES = list(CITYSCAPES_PALETTE)


@dataclass
class SyntheticFrame:
    """One frame: ``rgb``/``semantic`` (H, W, 3) uint8, ``sparse``/``depth``/``gt`` (H, W) float32 metres."""

    rgb: np.ndarray
    semantic: np.ndarray
    sparse: np.ndarray
    gt: np.ndarray
    depth: np.ndarray
    shadowed: bool


def _boxes(rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray, str]]:
    boxes = []
    for side in (-1, 1):  # building facades on both sides
        z = 4.0
        while z < 80:
            length = rng.uniform(8, 20)
            x0 = side * rng.uniform(7.5, 10)
            lo = np.array([min(x0, x0 + side * 6), -rng.uniform(6, 15), z])
            hi = np.array([max(x0, x0 + side * 6), 1.65, z + length])
            boxes.append((lo, hi, "building" if rng.random() > 0.25 else "vegetation"))
            z += length + rng.uniform(0, 4)
    for _ in range(rng.integers(2, 6)):  # parked and oncoming cars
        x = rng.choice([-4.2, -1.8, 1.8, 4.2]) + rng.uniform(-0.3, 0.3)
        z = rng.uniform(6, 45)
        lo = np.array([x - 0.9, 1.65 - 1.5, z])
        boxes.append((lo, lo + np.array([1.8, 1.5, 4.2]), "car"))
    for _ in range(rng.integers(1, 4)):  # poles
        x, z = rng.choice([-5.6, 5.6]), rng.uniform(5, 40)
        boxes.append((np.array([x - 0.1, -4.0, z]), np.array([x + 0.1, 1.65, z + 0.2]), "pole"))
    return boxes


def make_frame(height: int = 128, width: int = 416, seed: int = 0, shadow: bool | None = None) -> SyntheticFrame:
    """Generate one scene, deterministic in ``seed``.

    Args:
        height, width: image size (any; KITTI is about 375 x 1242).
        seed: random seed.
        shadow: cast a shadow across the road (random when None).
    """
    rng = np.random.default_rng(seed)
    f = 721.5 * width / 1242.0
    cx, cy = width / 2.0, height * 0.47
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    rays = np.stack(((u + 0.5 - cx) / f, (v + 0.5 - cy) / f, np.ones_like(u)), axis=-1)  # camera: x right, y down
    depth = np.full((height, width), np.inf)
    label = np.full((height, width), _CLASSES.index("sky"), dtype=np.int64)
    t_ground = np.where(rays[..., 1] > 1e-6, 1.65 / np.maximum(rays[..., 1], 1e-6), np.inf)  # camera 1.65 m up
    x_ground = rays[..., 0] * t_ground
    ground = np.isfinite(t_ground) & (t_ground < 120)
    depth[ground] = t_ground[ground]
    label[ground] = np.where(np.abs(x_ground[ground]) < 6.0, _CLASSES.index("road"), _CLASSES.index("sidewalk"))
    for lo, hi, cls in _boxes(rng):  # slab test for ray/box intersection; z of the hit is the depth
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = lo / rays, hi / rays
        tmin = np.nanmax(np.minimum(t1, t2), axis=-1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (tmax >= tmin) & (tmin > 0) & (tmin < depth)
        depth[hit] = tmin[hit]
        label[hit] = _CLASSES.index(cls)
    sky = ~np.isfinite(depth)
    palette = np.array([CITYSCAPES_PALETTE[c] for c in _CLASSES], dtype=np.uint8)
    albedo = np.array([_ALBEDO[c] for c in _CLASSES], dtype=np.float64)
    shade = 0.75 + 0.25 * rng.random() + 0.08 * rng.standard_normal((height, width))
    if shadow is None:
        shadow = bool(rng.random() < 0.5)
    if shadow:  # a diagonal band of shadow across the lower image, whatever the class
        band = np.abs((v / height - 0.55) - 0.4 * (u / width - rng.uniform(0.3, 0.7))) < rng.uniform(0.06, 0.15)
        shade = np.where(band & ~sky, shade * 0.35, shade)
    rgb = np.clip(albedo[label] * shade[..., None], 0, 255).astype(np.uint8)
    depth = np.where(sky, 0.0, depth).astype(np.float32)
    # LiDAR: 64 beams between +2 and -24.8 degrees, ~0.09 degree azimuth steps (HDL-64E).
    sparse = np.zeros_like(depth)
    elevation = np.deg2rad(np.linspace(2.0, -24.8, 64))
    rows = np.round(cy - f * np.tan(elevation)).astype(int)
    step = max(1, round(f * np.deg2rad(0.09) * 2.5))
    for r in rows[(rows >= 0) & (rows < height)]:
        cols = np.arange(int(rng.integers(0, step)), width, step)
        sparse[r, cols] = depth[r, cols]
    sparse[sparse > 80] = 0
    keep = rng.random(depth.shape) < 0.16 / max(1e-6, float((depth > 0).mean()))
    gt = np.where(keep & (depth > 0) & (depth < 80), depth, 0.0).astype(np.float32)
    quantise = lambda d: (np.round(d * 256.0) / 256.0).astype(np.float32)  # noqa: E731 (uint16 PNG encoding)
    return SyntheticFrame(
        rgb=rgb, semantic=palette[label], sparse=quantise(sparse), gt=quantise(gt), depth=depth, shadowed=shadow
    )
