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

Two styles (:data:`SCENE_STYLES`, the ``style`` argument of :func:`make_frame`):

``"ideal"`` (the default, the scenes above): every surface returns the LiDAR and, but for shadows,
colour edges are depth edges, so a semantic map says nothing the image does not.

``"realistic"``: the same streets, drawn from the same per-frame generator, with what makes
semantics informative on real roads. LiDAR failures tied to classes: 20 % of cars have dark paint
(15 % of beams return), 20 % glossy paint (35 % of beams mirrored off the face, range too long; 15 %
lost); every car has a glass cabin (70 % of beams return from the next surface behind the car, the
rest nothing); building windows are glass (15 % of beams return from 2-10 m inside, the rest
nothing); echoes weaken at grazing incidence and beyond 25 m (the far road thins out); sky returns
nothing. Colour edges without depth edges: hard shadows, road markings (dashed edge lines, zebra
crossings, stop lines, arrows), posters with stripes or checks on 40 % of facades. Depth edges
without colour edges: in half the frames a grey kerb-side car before facades of the same grey,
half the poles coloured like the facade behind them under the frame's sun. The ground truth is
still the exact depth of the first surface (glass included) and the labels the exact classes;
``SyntheticFrame.material`` and ``meta`` say what was applied.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from semattnet.data.io import DEPTH_SCALE
from semattnet.data.palette import TRAIN_CLASSES

__all__ = ["CITYSCAPES_PALETTE", "KITTI_K", "MATERIALS", "SCENE_STYLES", "SyntheticFrame", "make_frame"]

#: Scene styles of :func:`make_frame` (the first is the default).
SCENE_STYLES: tuple[str, ...] = ("ideal", "realistic")
#: Surfaces as the LiDAR sees them (``SyntheticFrame.material`` indexes this): dark paint returns few
#: points, glossy paint mirrors some beams (range too long), glass lets beams through or loses them.
MATERIALS: tuple[str, ...] = ("matte", "dark", "glossy", "glass")
_MAT = {m: i for i, m in enumerate(MATERIALS)}

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
    #: (H, W) uint8 index into MATERIALS of the surface each pixel sees (all "matte" in the ideal style).
    material: np.ndarray | None = None
    #: (H, W) bool: road markings and posters of the realistic style (colour edges on flat surfaces).
    paint: np.ndarray | None = None


@dataclass
class _Box:
    lo: np.ndarray
    hi: np.ndarray
    cls: str
    albedo: np.ndarray
    material: str = "matte"  # a name in MATERIALS; "glass" boxes are car cabins (glass but for the roof)
    group: int = -1  # boxes of one car share a group
    poster: tuple[float, ...] | None = None  # see _dress_facades


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
    """Nearest hit along each ray: distance t (inf on a miss), box index (-1 ground, -2 sky), face axis.

    ``origin`` is one point (3,) or one per ray (N, 3).
    """
    n = dirs.shape[0]
    t_best = np.full(n, np.inf)
    idx = np.full(n, -2, dtype=np.int64)
    axis = np.full(n, 1, dtype=np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = (_CAM_HEIGHT - origin[..., 1]) / dirs[:, 1]
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


def _lidar(
    height: int, width: int, K: np.ndarray, boxes: list[_Box], rng: np.random.Generator, realistic: bool = False
) -> tuple[np.ndarray, dict[str, int]]:
    """Sparse depth from a simulated spinning LiDAR, projected into the camera with a z-buffer, and counts
    of what :func:`_sensor_effects` did (``realistic``; empty otherwise)."""
    n_beams = 64 if height >= 300 else max(16, round(64 * height / 352))
    elevation = np.deg2rad(np.linspace(2.0, -24.8, n_beams))
    # ~0.46 points per image column per beam: ~5 % valid pixels, as KITTI (4-6 %).
    n_az = max(8, round(0.46 * width))
    half_fov = np.arctan(width / 2 / K[0, 0]) * 1.05
    az = np.linspace(-half_fov, half_fov, n_az) + rng.uniform(0, 2 * half_fov / n_az)
    el, a = np.meshgrid(elevation, az, indexing="ij")
    dirs = np.stack((np.cos(el) * np.sin(a), -np.sin(el), np.cos(el) * np.cos(a)), axis=-1).reshape(-1, 3)
    t, idx, axis = _cast(_LIDAR_ORIGIN, dirs, boxes)
    stats: dict[str, int] = {}
    if realistic:
        t, stats = _sensor_effects(dirs, t, idx, axis, boxes, rng)
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
    return np.where(np.isfinite(sparse), sparse, 0.0), stats


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


def _road_half(boxes: list[_Box]) -> float:
    """Half the road's width, from the poles at the kerb (5 m without poles)."""
    return min(abs(b.lo[0]) for b in boxes if b.cls == "pole") - 0.4 if any(b.cls == "pole" for b in boxes) else 5.0


def _labels(view: _View, boxes: list[_Box]) -> np.ndarray:
    """(N,) class ids: boxes by class, the ground by its distance from the road's centre line."""
    labels = np.full(view.height * view.width, _ID["sky"], dtype=np.int64)
    box_cls = np.array([_ID[b.cls] for b in boxes] or [0], dtype=np.int64)
    labels[view.on_box] = box_cls[view.idx[view.on_box]]
    road_half = _road_half(boxes)
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
    albedo[facade & _window(points)] *= 0.45  # windows
    return albedo


def _window(points: np.ndarray) -> np.ndarray:
    """Which points (N, 3) of a facade lie on a window (a grid of 1.2 x 1.2 m panes)."""
    wy, wz = np.mod(points[:, 1], 3.0), np.mod(points[:, 2] + points[:, 0], 2.5)
    return (wy > 1.2) & (wy < 2.4) & (wz > 0.6) & (wz < 1.8)


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


# --- The "realistic" style: what real sensors and streets add (drawn after the boxes) ---------------

#: Share of cars with dark paint (few LiDAR returns) and with glossy paint (specular wrong returns).
_DARK_SHARE, _GLOSSY_SHARE = 0.2, 0.2
_P_DARK_RETURN = 0.15  # dark paint: most beams come back too weak
_P_GLOSSY_MIRROR, _P_GLOSSY_DROP = 0.35, 0.15  # glossy paint: mirrored beam (range too long) or none
_P_CAR_GLASS_THROUGH = 0.7  # car windows: the beam returns from the next surface behind, else nothing
_P_WINDOW_INTERIOR = 0.15  # building windows: a return from 2-10 m inside the room, else nothing
_GLASS_RGB = np.array([38.0, 52.0, 72.0])  # dark bluish glass
_MARKING_RGB = np.array([235.0, 235.0, 230.0])


@dataclass
class _Dress:
    """What the realistic style adds besides boxes: road markings, poles to colour like a facade, counts."""

    road_half: float
    markings: dict[str, Any]
    camo_poles: list[tuple[int, int]]  # (pole box, building box) to look alike under the sun
    meta: dict[str, Any]


def _dress_cars(rng: np.random.Generator, boxes: list[_Box]) -> list[_Box]:
    """Split every car into a body and a glass cabin; paint a share dark or glossy (the rest at least mid-grey)."""
    out: list[_Box] = []
    g = 0
    for b in boxes:
        if b.cls != "car":
            out.append(b)
            continue
        r = rng.random()
        material = "dark" if r < _DARK_SHARE else "glossy" if r < _DARK_SHARE + _GLOSSY_SHARE else "matte"
        albedo = rng.uniform(8, 30) * np.array([1.0, 1.0, 1.1]) if material == "dark" else np.maximum(b.albedo, 60)
        belt = b.hi[1] - 0.58 * (b.hi[1] - b.lo[1])  # y (down) of the belt line
        length = b.hi[2] - b.lo[2]
        cabin_lo = np.array([b.lo[0] + 0.06, b.lo[1], b.lo[2] + 0.18 * length])
        cabin_hi = np.array([b.hi[0] - 0.06, belt, b.hi[2] - 0.22 * length])
        out.append(_Box(np.array([b.lo[0], belt, b.lo[2]]), b.hi.copy(), "car", albedo, material, g))
        out.append(_Box(cabin_lo, cabin_hi, "car", albedo, "glass", g))
        g += 1
    return out


def _camouflage_car(rng: np.random.Generator, boxes: list[_Box], road_half: float) -> float:
    """With p = 0.5 paint one kerb-side car and the facades on its side the same grey; returns that side (0: none)."""
    kerb = sorted({b.group for b in boxes if b.cls == "car" and abs(b.lo[0] + b.hi[0]) / 2 > road_half / 2})
    if rng.random() >= 0.5 or not kerb:
        return 0.0
    group = kerb[int(rng.integers(len(kerb)))]
    grey = np.full(3, rng.uniform(80, 170))
    side = 0.0
    for b in boxes:
        if b.group == group:
            b.albedo, side = grey, float(np.sign(b.lo[0] + b.hi[0]))
            b.material = "glass" if b.material == "glass" else "matte"
    for b in boxes:
        if b.cls == "building" and b.hi[0] - b.lo[0] < 50 and np.sign(b.lo[0] + b.hi[0]) == side:
            b.albedo = grey.copy()
    return side


def _dress_facades(rng: np.random.Generator, boxes: list[_Box], road_half: float, grey_side: float) -> int:
    """Hang posters (stripes, checks or diagonals, 2.5-7 m wide) on 40 % of the facades, 50 % of end walls."""
    n = 0
    for b in boxes:
        end_wall = b.hi[0] - b.lo[0] > 50
        if b.cls != "building" or (not end_wall and np.sign(b.lo[0] + b.hi[0]) == grey_side):
            continue
        if rng.random() >= (0.5 if end_wall else 0.4):
            continue
        width, tall = rng.uniform(2.5, 7.0), rng.uniform(1.5, 3.5)
        if end_wall:  # on the face towards the camera, along x
            axis, s0 = 2, rng.uniform(-road_half - 4, road_half + 4 - width)
        else:  # on the face towards the road, along z
            axis, s0 = 0, rng.uniform(b.lo[2], max(b.lo[2], b.hi[2] - width))
        bottom = _CAM_HEIGHT - rng.uniform(0.3, 2.0)
        kind, period = int(rng.integers(3)), rng.uniform(0.25, 0.8)
        bright, dark = rng.uniform(170, 250, 3), rng.uniform(10, 70, 3)
        b.poster = (axis, s0, s0 + width, bottom - tall, bottom, kind, period, *bright, *dark)
        n += 1
    return n


def _camo_poles(rng: np.random.Generator, boxes: list[_Box]) -> list[tuple[int, int]]:
    """Pick half of the poles to be coloured like the facade behind them (seen from the camera)."""
    pairs = []
    for p, pole in enumerate(boxes):
        if pole.cls != "pole" or rng.random() >= 0.5:
            continue
        xp, zp = (pole.lo[0] + pole.hi[0]) / 2, pole.lo[2]
        for b, bld in enumerate(boxes):
            face = bld.hi[0] if xp < 0 else bld.lo[0]
            if bld.cls == "building" and bld.hi[0] - bld.lo[0] < 50 and face * xp > 0:
                if bld.lo[2] <= zp * face / xp <= bld.hi[2]:
                    pairs.append((p, b))
                    break
    return pairs


def _markings(rng: np.random.Generator) -> dict[str, Any]:
    """Road markings: dashed edge lines, maybe a zebra crossing, a stop line, up to two arrows."""
    zebra = float(rng.uniform(8, 35)) if rng.random() < 0.6 else None
    stop = (float(rng.uniform(6, 40)), float(rng.choice([-1, 1]))) if rng.random() < 0.5 else None
    arrows = [(float(rng.choice([-1, 1])), float(rng.uniform(6, 25))) for _ in range(int(rng.integers(0, 3)))]
    return {"edge_phase": float(rng.uniform(0, 5)), "zebra_z": zebra, "stop": stop, "arrows": arrows}


def _dress(rng: np.random.Generator, boxes: list[_Box]) -> tuple[list[_Box], _Dress]:
    """Everything the realistic style draws about the scene, right after :func:`_scene`."""
    road_half = _road_half(boxes)
    boxes = _dress_cars(rng, boxes)
    grey_side = _camouflage_car(rng, boxes, road_half)
    posters = _dress_facades(rng, boxes, road_half, grey_side)
    poles = _camo_poles(rng, boxes)
    markings = _markings(rng)
    bodies = [b.material for b in boxes if b.cls == "car" and b.material != "glass"]
    cars = {"cars": len(bodies), "dark": bodies.count("dark"), "glossy": bodies.count("glossy")}
    meta = {"cars": {**cars, "camouflaged": int(grey_side != 0)}, "posters": posters,
            "camouflaged_poles": len(poles), "markings": markings}  # fmt: skip
    return boxes, _Dress(road_half, markings, poles, meta)


def _camouflage_poles(boxes: list[_Box], dress: _Dress, sun: np.ndarray) -> None:
    """Colour the chosen poles so their front face renders as the facade behind (same albedo x sunlight)."""
    for p, b in dress.camo_poles:
        side = np.sign(boxes[p].lo[0] + boxes[p].hi[0])
        facade = 0.45 + 0.75 * np.clip(-(np.array([-side, 0.0, 0.0]) @ sun), 0, 1)
        front = 0.45 + 0.75 * np.clip(-(np.array([0.0, 0.0, -1.0]) @ sun), 0, 1)
        boxes[p].albedo = boxes[b].albedo * facade / front


def _posters(points: np.ndarray, idx: np.ndarray, axis: np.ndarray, boxes: list[_Box]):  # type: ignore[no-untyped-def]
    """Per point: on a poster (N,) and the poster's colour there (N, 3)."""
    on = np.zeros(len(idx), dtype=bool)
    colour = np.zeros((len(idx), 3))
    for b, box in enumerate(boxes):
        if box.poster is None:
            continue
        ax, s0, s1, y0, y1, kind, period, *cols = box.poster
        sel = np.flatnonzero((idx == b) & (axis == ax))
        s, y = points[sel, 2 if ax == 0 else 0], points[sel, 1]
        inside = (s > s0) & (s < s1) & (y > y0) & (y < y1)
        a, c = s / period, y / period
        pattern = (np.mod(a, 1) < 0.5, (np.floor(a) + np.floor(c)) % 2 == 0, np.mod(a + c, 1) < 0.5)[int(kind)]
        on[sel[inside]] = True
        colour[sel[inside]] = np.where(pattern[inside, None], cols[:3], cols[3:])
    return on, colour


def _surfaces(points: np.ndarray, idx: np.ndarray, axis: np.ndarray, boxes: list[_Box]):  # type: ignore[no-untyped-def]
    """Per ray hit (realistic style): material code (index into MATERIALS), on a poster, poster colour."""
    on_box = idx >= 0
    safe = np.where(on_box, idx, 0)
    box_mat = np.array([_MAT[b.material] for b in boxes] or [0])
    is_building = np.array([b.cls == "building" for b in boxes] or [False])
    material = np.where(on_box, box_mat[safe], _MAT["matte"])
    material[(material == _MAT["glass"]) & (axis == 1)] = _MAT["matte"]  # a cabin's roof is not glass
    poster, colour = _posters(points, idx, axis, boxes)
    facade = np.flatnonzero(on_box & is_building[safe] & (axis != 1) & ~poster)
    material[facade[_window(points[facade])]] = _MAT["glass"]
    return material, poster, colour


def _road_markings(points: np.ndarray, road: np.ndarray, dress: _Dress) -> np.ndarray:
    """Which road points carry paint (the realistic style's markings; the centre line is in :func:`_albedo`)."""
    on = np.flatnonzero(road)
    x, z, rh, m = points[on, 0], points[on, 2], dress.road_half, dress.markings
    paint = (np.abs(np.abs(x) - (rh - 0.3)) < 0.08) & (np.mod(z + m["edge_phase"], 5.0) < 2.5)
    if m["zebra_z"] is not None:
        paint |= (z > m["zebra_z"]) & (z < m["zebra_z"] + 3.0) & (np.mod(x + rh, 1.0) < 0.5) & (np.abs(x) < rh - 0.5)
    if m["stop"] is not None:
        paint |= (np.abs(z - m["stop"][0]) < 0.2) & (x * m["stop"][1] > 0) & (np.abs(x) < rh - 0.3)
    for side, z0 in m["arrows"]:
        dx, dz = np.abs(x - side * rh / 2), z - z0
        shaft = (dx < 0.12) & (dz > 0) & (dz < 2.5)
        head = (dz >= 2.5) & (dz < 4.0) & (dx < 0.5 * (1 - (dz - 2.5) / 1.5))
        paint |= shaft | head
    out = np.zeros(len(road), dtype=bool)
    out[on[paint]] = True
    return out


def _decorate(
    view: _View, labels: np.ndarray, albedo: np.ndarray, surfaces: tuple[np.ndarray, ...], dress: _Dress
) -> tuple[np.ndarray, np.ndarray]:
    """Realistic albedo (glass dark bluish, posters, road markings) and where paint lies (no depth edges)."""
    material, poster, colour = surfaces
    albedo = albedo.copy()
    albedo[material == _MAT["glass"]] = _GLASS_RGB
    albedo[poster] = colour[poster]
    marking = _road_markings(view.points, labels == _ID["road"], dress)
    albedo[marking] = _MARKING_RGB
    return albedo, poster | marking


def _reflected_range(points: np.ndarray, dirs: np.ndarray, axis: np.ndarray, boxes: list[_Box]) -> np.ndarray:
    """Range from a mirroring box face (``axis``) along the reflected ray to the next surface (inf: none)."""
    r = dirs.copy()
    r[np.arange(len(r)), axis] *= -1
    t, _, _ = _cast(points + 1e-4 * r, r, boxes)
    return t


def _through_range(dirs: np.ndarray, idx: np.ndarray, boxes: list[_Box]) -> np.ndarray:
    """Range from the LiDAR to the next surface behind the car each ray hit (cast without that car)."""
    group = np.array([b.group for b in boxes])[idx]
    t = np.full(len(dirs), np.inf)
    for g in np.unique(group):
        sel = group == g
        t[sel], _, _ = _cast(_LIDAR_ORIGIN, dirs[sel], [b for b in boxes if b.group != g])
    return t


def _sensor_effects(
    dirs: np.ndarray, t: np.ndarray, idx: np.ndarray, axis: np.ndarray, boxes: list[_Box], rng: np.random.Generator
) -> tuple[np.ndarray, dict[str, int]]:
    """Realistic LiDAR returns: ranges (inf: none) after paint, glass, range and grazing effects, and counts."""
    n = len(t)
    hit = np.isfinite(t) & (t < _MAX_RANGE)
    points = _LIDAR_ORIGIN + dirs * np.where(hit, t, 0.0)[:, None]
    material, _, _ = _surfaces(points, idx, axis, boxes)
    is_car = np.array([b.cls == "car" for b in boxes] or [False])[np.where(idx >= 0, idx, 0)] & (idx >= 0)
    u, v, inside = rng.random(n), rng.random(n), rng.uniform(2.0, 10.0, n)
    dark, glossy = hit & (material == _MAT["dark"]), hit & (material == _MAT["glossy"])
    car_glass = hit & (material == _MAT["glass"]) & is_car
    window = hit & (material == _MAT["glass"]) & ~is_car
    mirror, through = glossy & (v >= 1 - _P_GLOSSY_MIRROR), car_glass & (v < _P_CAR_GLASS_THROUGH)
    interior = window & (v < _P_WINDOW_INTERIOR)
    out = np.where(hit, t, np.inf)
    out[mirror] = t[mirror] + _reflected_range(points[mirror], dirs[mirror], axis[mirror], boxes)
    out[through] = _through_range(dirs[through], idx[through], boxes)
    out[interior] += inside[interior]
    dropped = {"dark": dark & (v >= _P_DARK_RETURN), "glossy": glossy & (v < _P_GLOSSY_DROP),
               "glass": (car_glass & ~through) | (window & ~interior)}  # fmt: skip
    # Weak echoes: fewer returns at grazing incidence (cosine to the normal below ~0.12) and beyond 25 m.
    cos_in = np.abs(dirs[np.arange(n), np.where(idx >= 0, axis, 1)])
    rng_m = np.where(np.isfinite(out), out, 0.0)
    p = np.clip(0.25 + 6.0 * cos_in, 0, 1) * np.clip(1 - np.maximum(0, rng_m - 25) / 70, 0.2, 1)
    gone = dropped["dark"] | dropped["glossy"] | dropped["glass"]
    dropped["range_grazing"] = hit & ~gone & np.isfinite(out) & (u >= p)
    out[gone | dropped["range_grazing"]] = np.inf
    kept = np.isfinite(out) & (out < _MAX_RANGE)
    stats = {"rays": n, "first_surface_hits": int(hit.sum()), "returns": int(kept.sum()),
             **{f"dropped_{k}": int(m.sum()) for k, m in dropped.items()},
             "wrong_glossy": int((mirror & kept).sum()), "wrong_car_glass": int((through & kept).sum()),
             "wrong_window": int((interior & kept).sum())}  # fmt: skip
    return out, stats


def _colours(
    view: _View, labels: np.ndarray, boxes: list[_Box], dress: _Dress | None, sun: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) albedo, (N,) material codes and (N,) paint mask, with the realistic style's glass, posters,
    markings and camouflage (the ideal style: all matte, no paint beyond the centre line)."""
    n = view.height * view.width
    if dress is None:
        return _albedo(view, labels, boxes), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    _camouflage_poles(boxes, dress, sun)  # needs the sun; draws nothing
    surfaces = _surfaces(view.points, view.idx, view.axis, boxes)
    albedo, paint = _decorate(view, labels, _albedo(view, labels, boxes), surfaces, dress)
    return albedo, np.where(view.far, _MAT["matte"], surfaces[0]), paint


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
    height: int = 352,
    width: int = 1216,
    seed: int = 0,
    shadow: bool | None = None,
    size_of_kitti: bool = True,
    style: str = "ideal",
) -> SyntheticFrame:
    """Generate one scene, deterministic in ``seed`` (and ``style``).

    Args:
        height: image height (any; KITTI's raw frames are about 375 x 1242).
        width: image width.
        seed: random seed.
        shadow: add a hard shadow band across the scene (random, p = 0.5, when None).
        size_of_kitti: scale the intrinsics so the field of view is KITTI's at this width.
        style: one of :data:`SCENE_STYLES`: ``"ideal"`` (every surface returns LiDAR, colour edges are
            depth edges but for shadows) or ``"realistic"`` (see the module docstring).

    Raises:
        ValueError: unknown ``style``.
    """
    if style not in SCENE_STYLES:
        raise ValueError(f"unknown scene style {style!r}; expected one of {SCENE_STYLES}")
    rng = np.random.default_rng(seed)  # every step below draws from it, in this order
    K = _intrinsics(height, width, size_of_kitti)
    boxes, dress = _scene(rng), None
    if style == "realistic":
        boxes, dress = _dress(rng, boxes)
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
    albedo, material, paint = _colours(view, labels, boxes, dress, sun)
    rgb = _render(view, albedo, light, exposure, rng)
    labels = labels.reshape(height, width)
    depth = np.where(view.far.reshape(height, width), 0.0, view.points[:, 2].reshape(height, width))
    sparse, lidar = _lidar(height, width, K, boxes, rng, realistic=dress is not None)
    gt = _ground_truth(depth, K, rng)
    meta = {"seed": seed, "style": style, "shadow_band_z": list(band), "sun": sun.tolist(), "exposure": exposure}
    if dress is not None:
        meta |= {**dress.meta, "lidar": lidar}
    return SyntheticFrame(
        rgb=rgb,
        semantic=_PALETTE[labels],
        sparse=_quantise(sparse),
        gt=_quantise(gt),
        depth=depth.astype(np.float32),
        labels=labels,
        K=K,
        shadowed=shadow,
        meta=meta,
        material=material.astype(np.uint8).reshape(height, width),
        paint=paint.reshape(height, width),
    )
