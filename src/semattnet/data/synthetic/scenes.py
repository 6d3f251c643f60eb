"""Procedural KITTI-like driving scenes with exact depth (issue: no KITTI at hand).

A pinhole camera with KITTI's intrinsics (scaled to the image size) 1.65 m above a road looks
down a street: road with lane markings, sidewalks, building facades with windows, trees, parked
and oncoming cars, poles, pedestrians, sky. Surfaces are axis-aligned boxes and the ground plane,
so every pixel's depth is exact (ray casting). Sunlight gives Lambertian shading and shadows cast
by every object onto the road; ``shadow=True`` adds a hard shadow band across the whole scene
(an overpass), the illumination change the paper's semantic branch is meant to be robust to.

The sparse input comes from a simulated 64-beam spinning LiDAR mounted 0.27 m behind and 0.08 m
above the camera (so, as in KITTI, it sees a little behind foreground edges): rays are cast from
the sensor, the hits projected into the camera with a z-buffer, ~5 % of pixels valid, 2 cm range
noise. The ground truth keeps ~16 % of pixels of the exact depth below the LiDAR's top beam,
as dense as KITTI's accumulated maps. Labels use the Cityscapes trainId palette.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semattnet.data.io import DEPTH_SCALE
from semattnet.data.palette import TRAIN_CLASSES

__all__ = ["CITYSCAPES_PALETTE", "KITTI_K", "SyntheticFrame", "make_frame"]

#: Cityscapes trainId colours of the classes the generator uses (class name -> RGB).
CITYSCAPES_PALETTE: dict[str, tuple[int, int, int]] = {
    c: dict(TRAIN_CLASSES)[c] for c in ("road", "sidewalk", "building", "pole", "vegetation", "sky", "person", "car")
}
_CLASSES = list(CITYSCAPES_PALETTE)
_ID = {c: i for i, c in enumerate(_CLASSES)}
#: (len(_CLASSES), 3) uint8 colour table indexed by label.
_PALETTE = np.array([CITYSCAPES_PALETTE[c] for c in _CLASSES], dtype=np.uint8)

#: KITTI camera 02 intrinsics at 1242x375 (drive 2011_09_26).
KITTI_K = np.array([[721.5377, 0.0, 609.5593], [0.0, 721.5377, 172.854], [0.0, 0.0, 1.0]])
_CAM_HEIGHT = 1.65
_LIDAR_ORIGIN = np.array([0.0, -0.08, -0.27])  # camera frame: x right, y down, z forward
_MAX_RANGE = 80.0


@dataclass
class SyntheticFrame:
    """One frame. Images are (H, W, 3) uint8; depths (H, W) float32 metres, 0 = none."""

    rgb: np.ndarray
    semantic: np.ndarray
    sparse: np.ndarray
    gt: np.ndarray
    depth: np.ndarray  # exact depth of every pixel (0 for sky)
    labels: np.ndarray  # (H, W) int64 index into CITYSCAPES_PALETTE order
    K: np.ndarray  # 3x3 intrinsics
    shadowed: bool
    meta: dict = field(default_factory=dict)


@dataclass
class _Box:
    lo: np.ndarray
    hi: np.ndarray
    cls: str
    albedo: np.ndarray


def _scene(rng: np.random.Generator) -> list[_Box]:
    boxes: list[_Box] = []

    def add(lo, hi, cls, albedo) -> None:  # type: ignore[no-untyped-def]
        boxes.append(_Box(np.asarray(lo, float), np.asarray(hi, float), cls, np.asarray(albedo, float)))

    road_half = rng.uniform(3.5, 6.0)
    walk = rng.uniform(2.0, 3.5)
    for side in (-1, 1):
        z = rng.uniform(-2, 6)
        while z < 90:
            length = rng.uniform(6, 22)
            inner = side * (road_half + walk + rng.uniform(0, 1.5))
            x0, x1 = sorted((inner, inner + side * rng.uniform(5, 12)))
            if rng.random() < 0.25:  # a tree: trunk and crown
                cx = inner + side * 1.5
                add([cx - 0.2, -2.5, z + 2], [cx + 0.2, _CAM_HEIGHT, z + 2.4], "vegetation", [70, 55, 40])
                add([cx - 2, -6.5, z], [cx + 2, -2.5, z + 4.4], "vegetation", rng.uniform([40, 80, 20], [80, 130, 50]))
            else:
                height = rng.uniform(5, 18)
                add([x0, _CAM_HEIGHT - height, z], [x1, _CAM_HEIGHT, z + length], "building",
                    rng.uniform([110, 90, 70], [200, 170, 150]))  # fmt: skip
            z += length + rng.uniform(0, 5)
    end = rng.uniform(70, 100)  # the street ends in a facade, so depth stays within ~100 m
    add([-60, _CAM_HEIGHT - rng.uniform(8, 20), end], [60, _CAM_HEIGHT, end + 5], "building",
        rng.uniform([110, 90, 70], [200, 170, 150]))  # fmt: skip
    for _ in range(int(rng.integers(2, 7))):  # cars in lanes and parked at the kerb
        lane = rng.choice([-1, 1]) * rng.choice([road_half - 1.2, road_half / 3])
        z = rng.uniform(5, 55)
        w, h, length = rng.uniform(1.6, 2.0), rng.uniform(1.3, 1.7), rng.uniform(3.8, 4.8)
        add([lane - w / 2, _CAM_HEIGHT - h, z], [lane + w / 2, _CAM_HEIGHT, z + length], "car",
            rng.uniform([20, 20, 20], [220, 220, 220]))  # fmt: skip
    for _ in range(int(rng.integers(1, 5))):  # poles at the kerb
        x, z = rng.choice([-1, 1]) * (road_half + 0.4), rng.uniform(4, 50)
        add([x - 0.08, _CAM_HEIGHT - 5.5, z], [x + 0.08, _CAM_HEIGHT, z + 0.16], "pole", [120, 120, 125])
    for _ in range(int(rng.integers(0, 5))):  # pedestrians on the sidewalk
        x, z = rng.choice([-1, 1]) * (road_half + rng.uniform(0.5, walk)), rng.uniform(4, 35)
        add([x - 0.25, _CAM_HEIGHT - rng.uniform(1.5, 1.9), z], [x + 0.25, _CAM_HEIGHT, z + 0.4], "person",
            rng.uniform([40, 30, 30], [200, 160, 160]))  # fmt: skip
    return boxes


def _cast(origin: np.ndarray, dirs: np.ndarray, boxes: list[_Box]):  # type: ignore[no-untyped-def]
    """Nearest hit along each ray: distance t (inf on a miss), box index (-1 ground, -2 sky), face axis."""
    n = dirs.shape[0]
    t_best = np.full(n, np.inf)
    idx = np.full(n, -2, dtype=np.int64)
    axis = np.full(n, 1, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = (_CAM_HEIGHT - origin[1]) / dirs[:, 1]
    ground = (dirs[:, 1] > 1e-9) & (t_ground > 0)
    t_best[ground] = t_ground[ground]
    idx[ground] = -1
    inv = [1.0 / np.where(np.abs(dirs[:, k]) < 1e-12, 1e-12, dirs[:, k]) for k in range(3)]
    for b, box in enumerate(boxes):  # slab test, one axis at a time (no reductions over a tiny axis)
        near, far = [], []
        for k in range(3):
            t1, t2 = (box.lo[k] - origin[k]) * inv[k], (box.hi[k] - origin[k]) * inv[k]
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


def _cast_camera(K: np.ndarray, height: int, width: int, boxes: list[_Box]):  # type: ignore[no-untyped-def]
    """:func:`_cast` for the camera's pixel rays, testing each box only inside its screen rectangle."""
    v, u = np.mgrid[0:height, 0:width]
    dirs = np.stack(((u + 0.5 - K[0, 2]) / K[0, 0], (v + 0.5 - K[1, 2]) / K[1, 1], np.ones((height, width))), -1)
    t_best, idx, axis = (a.reshape(height, width) for a in _cast(np.zeros(3), dirs.reshape(-1, 3), []))
    for b, box in enumerate(boxes):
        lo, hi = box.lo.copy(), box.hi.copy()
        lo[2] = max(lo[2], 0.1)  # the part in front of the camera
        if hi[2] <= lo[2]:
            continue
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        pu = K[0, 0] * corners[:, 0] / corners[:, 2] + K[0, 2]
        pv = K[1, 1] * corners[:, 1] / corners[:, 2] + K[1, 2]
        u0, u1 = max(0, int(np.floor(pu.min()))), min(width, int(np.ceil(pu.max())) + 1)
        v0, v1 = max(0, int(np.floor(pv.min()))), min(height, int(np.ceil(pv.max())) + 1)
        if u0 >= u1 or v0 >= v1:
            continue
        win = (slice(v0, v1), slice(u0, u1))
        d = dirs[win].reshape(-1, 3)
        t, _, ax = _cast(np.zeros(3), d, [box])
        t = t.reshape(v1 - v0, u1 - u0)
        hit = t < t_best[win]
        t_best[win] = np.where(hit, t, t_best[win])
        idx[win] = np.where(hit, b, idx[win])
        axis[win] = np.where(hit, ax.reshape(t.shape), axis[win])
    return dirs.reshape(-1, 3), t_best.reshape(-1), idx.reshape(-1), axis.reshape(-1)


def _convex_hull(points: np.ndarray) -> np.ndarray:
    pts = sorted(map(tuple, points))
    if len(pts) <= 2:
        return np.array(pts)

    def half(seq):  # type: ignore[no-untyped-def]
        out: list = []
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


def _ground_shadow(xz: np.ndarray, boxes: list[_Box], sun: np.ndarray) -> np.ndarray:
    """Which ground points (N, 2: x, z) lie in the shadow some box casts along ``sun``."""
    shadow = np.zeros(len(xz), dtype=bool)
    for box in boxes:
        corners = np.array([[x, y, z] for x in (box.lo[0], box.hi[0]) for y in (box.lo[1], box.hi[1])
                            for z in (box.lo[2], box.hi[2])])  # fmt: skip
        t = (_CAM_HEIGHT - corners[:, 1]) / sun[1]  # slide each corner along the sun ray to the ground
        hull = _convex_hull(corners[:, [0, 2]] + t[:, None] * sun[[0, 2]])
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


def _lidar(height: int, width: int, K: np.ndarray, boxes: list[_Box], rng: np.random.Generator) -> np.ndarray:
    """Sparse depth from a simulated spinning LiDAR, projected into the camera with a z-buffer."""
    n_beams = 64 if height >= 300 else max(16, round(64 * height / 352))
    elevation = np.deg2rad(np.linspace(2.0, -24.8, n_beams))
    # ~0.46 points per image column per beam: ~5 % valid pixels, as KITTI (4-6 %).
    n_az = max(8, round(0.46 * width))
    half_fov = np.arctan(width / 2 / K[0, 0]) * 1.05
    az = np.linspace(-half_fov, half_fov, n_az) + rng.uniform(0, 2 * half_fov / n_az)
    el, a = np.meshgrid(elevation, az, indexing="ij")
    dirs = np.stack((np.cos(el) * np.sin(a), -np.sin(el), np.cos(el) * np.cos(a)), axis=-1).reshape(-1, 3)
    t, _, _ = _cast(_LIDAR_ORIGIN, dirs, boxes)
    ok = np.isfinite(t) & (t < _MAX_RANGE)
    t = t[ok] + rng.normal(0.0, 0.02, ok.sum())  # range noise
    points = _LIDAR_ORIGIN + dirs[ok] * t[:, None]
    z = points[:, 2]
    front = z > 0.5
    points, z = points[front], z[front]
    u = np.floor(K[0, 0] * points[:, 0] / z + K[0, 2]).astype(np.int64)
    v = np.floor(K[1, 1] * points[:, 1] / z + K[1, 2]).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    u, v, z = u[inside], v[inside], z[inside]
    sparse = np.full((height, width), np.inf)
    np.minimum.at(sparse, (v, u), z)  # z-buffer
    return np.where(np.isfinite(sparse), sparse, 0.0)


@dataclass
class _View:
    """What the camera sees, per pixel (flattened row-major): ray, what it hits and where."""

    height: int
    width: int
    dirs: np.ndarray  # (N, 3) pixel rays, z = 1
    idx: np.ndarray  # (N,) box index hit, -1 ground, -2 sky (or beyond 150 m)
    axis: np.ndarray  # (N,) axis of the box face hit
    far: np.ndarray  # (N,) sky or beyond 150 m: no surface
    points: np.ndarray  # (N, 3) surface points in the camera frame (0 where far)
    on_box: np.ndarray  # (N,) the ray hits a box
    ground: np.ndarray  # (N,) the ray hits the ground


def _intrinsics(height: int, width: int, size_of_kitti: bool) -> np.ndarray:
    """KITTI's intrinsics, scaled to KITTI's field of view at this width when ``size_of_kitti``."""
    K = KITTI_K.copy()
    if size_of_kitti:
        s = width / 1242.0
        K[0, 0] = K[1, 1] = KITTI_K[0, 0] * s
        K[0, 2] = width / 2.0
        K[1, 2] = height - (375.0 - KITTI_K[1, 2]) * s  # keep the horizon where KITTI has it
    return K


def _view(K: np.ndarray, height: int, width: int, boxes: list[_Box]) -> _View:
    """Cast the camera's rays; hits beyond 150 m count as sky."""
    dirs, t, idx, axis = _cast_camera(K, height, width, boxes)
    far = ~np.isfinite(t) | (t * dirs[:, 2] > 150)
    idx[far] = -2
    points = dirs * np.where(far, 0.0, t)[:, None]
    return _View(height, width, dirs, idx, axis, far, points, idx >= 0, idx == -1)


def _labels(view: _View, boxes: list[_Box]) -> np.ndarray:
    """(N,) class ids: boxes by class, the ground by its distance from the road's centre line."""
    labels = np.full(view.height * view.width, _ID["sky"], dtype=np.int64)
    box_cls = np.array([_ID[b.cls] for b in boxes] or [0], dtype=np.int64)
    labels[view.on_box] = box_cls[view.idx[view.on_box]]
    road_half = (
        min(abs(b.lo[0]) for b in boxes if b.cls == "pole") - 0.4 if any(b.cls == "pole" for b in boxes) else 5.0
    )
    labels[view.ground] = np.where(np.abs(view.points[view.ground, 0]) < road_half, _ID["road"], _ID["sidewalk"])
    return labels


def _albedo(view: _View, labels: np.ndarray, boxes: list[_Box]) -> np.ndarray:
    """(N, 3) surface colours: box albedos, road with lane markings, sidewalk, facades with windows."""
    points, on_box = view.points, view.on_box
    albedo = np.zeros((view.height * view.width, 3))
    albedo[on_box] = np.array([b.albedo for b in boxes])[view.idx[on_box]]
    road = labels == _ID["road"]
    albedo[road] = [85, 85, 90]
    albedo[labels == _ID["sidewalk"]] = [150, 140, 135]
    lane = road & (np.abs(points[:, 0]) < 0.08) & (np.mod(points[:, 2], 6.0) < 3.0)
    albedo[lane] = [235, 235, 230]
    facade = on_box & (labels == _ID["building"]) & (view.axis != 1)
    wy, wz = np.mod(points[:, 1], 3.0), np.mod(points[:, 2] + points[:, 0], 2.5)
    albedo[facade & (wy > 1.2) & (wy < 2.4) & (wz > 0.6) & (wz < 1.8)] *= 0.45  # windows
    return albedo


def _sun(rng: np.random.Generator) -> np.ndarray:
    """A random unit direction the sunlight travels (downwards)."""
    sun = np.array([rng.uniform(-0.6, 0.6), 1.0, rng.uniform(-0.3, 0.8)])
    sun /= np.linalg.norm(sun)
    return sun


def _sunlight(view: _View, boxes: list[_Box], sun: np.ndarray, exposure: float) -> np.ndarray:
    """(N,) light: ``exposure`` x (ambient + Lambertian sun), no sun where a box shades the ground."""
    normal = np.zeros((view.height * view.width, 3))
    normal[view.ground] = [0, -1, 0]
    on = np.flatnonzero(view.on_box)
    normal[on, view.axis[on]] = -np.sign(view.dirs[on, view.axis[on]])
    lit = np.clip(-(normal @ sun), 0.0, 1.0)
    in_shadow = np.zeros(view.height * view.width, dtype=bool)
    in_shadow[view.ground] = _ground_shadow(view.points[view.ground][:, [0, 2]], boxes, sun)
    return exposure * (0.45 + 0.75 * lit * ~in_shadow)


def _overpass(view: _View, light: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, tuple[float, float]]:
    """Shade a random band of the street (an overpass), whatever the surface: new light, the band's z range."""
    z0 = rng.uniform(6, 18)
    band = (z0, z0 + rng.uniform(4, 9))
    z = view.points[:, 2]
    return np.where(~view.far & (z > band[0]) & (z < band[1]), light * 0.3, light), band


def _render(
    view: _View, albedo: np.ndarray, light: np.ndarray, exposure: float, rng: np.random.Generator
) -> np.ndarray:
    """(H, W, 3) uint8 image: albedo x light x 6 % noise, and a vertical gradient for the sky."""
    h, w, far = view.height, view.width, view.far
    noise = 1.0 + 0.06 * rng.standard_normal(h * w)
    rgb = albedo * (light * noise)[:, None]
    sky_v = np.mgrid[0:h, 0:w][0].reshape(-1)[far] / max(1, h)
    rgb[far] = np.stack((150 + 60 * sky_v, 185 + 40 * sky_v, 235 + 0 * sky_v), -1) * exposure
    return np.clip(rgb, 0, 255).astype(np.uint8).reshape(h, w, 3)


def _ground_truth(depth: np.ndarray, K: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """~16 % of the pixels the LiDAR's field of view covers, exact depth, in range (0 elsewhere)."""
    height, width = depth.shape
    top_row = int(np.clip(K[1, 2] - K[1, 1] * np.tan(np.deg2rad(2.0)), 0, height - 1))
    eligible = (depth > 0) & (depth < _MAX_RANGE)
    eligible[:top_row] = False
    p = min(1.0, 0.17 * height * width / max(1, eligible.sum()))
    return np.where(eligible & (rng.random((height, width)) < p), depth, 0.0)


def _quantise(d: np.ndarray) -> np.ndarray:
    """Depth as a KITTI uint16 PNG stores it (1/256 m steps), as float32 metres."""
    return (np.round(d * DEPTH_SCALE) / DEPTH_SCALE).astype(np.float32)


def make_frame(
    height: int = 352, width: int = 1216, seed: int = 0, shadow: bool | None = None, size_of_kitti: bool = True
) -> SyntheticFrame:
    """Generate one scene, deterministic in ``seed``.

    Args:
        height, width: image size (any; KITTI's raw frames are about 375 x 1242).
        seed: random seed.
        shadow: add a hard shadow band across the scene (random, p = 0.5, when None).
        size_of_kitti: scale the intrinsics so the field of view is KITTI's at this width.
    """
    rng = np.random.default_rng(seed)  # every step below draws from it, in this order
    K = _intrinsics(height, width, size_of_kitti)
    boxes = _scene(rng)
    view = _view(K, height, width, boxes)
    labels = _labels(view, boxes)
    sun = _sun(rng)
    exposure = rng.uniform(0.7, 1.15)
    light = _sunlight(view, boxes, sun, exposure)
    if shadow is None:
        shadow = bool(rng.random() < 0.5)
    band = (0.0, 0.0)
    if shadow:
        light, band = _overpass(view, light, rng)
    rgb = _render(view, _albedo(view, labels, boxes), light, exposure, rng)
    labels = labels.reshape(height, width)
    depth = np.where(view.far.reshape(height, width), 0.0, view.points[:, 2].reshape(height, width))
    sparse = _lidar(height, width, K, boxes, rng)
    gt = _ground_truth(depth, K, rng)
    return SyntheticFrame(
        rgb=rgb,
        semantic=_PALETTE[labels],
        sparse=_quantise(sparse),
        gt=_quantise(gt),
        depth=depth.astype(np.float32),
        labels=labels,
        K=K,
        shadowed=shadow,
        meta={"seed": seed, "shadow_band_z": list(band), "sun": sun.tolist(), "exposure": exposure},
    )
