"""Procedural KITTI-like driving scenes with exact depth (issue: no KITTI at hand).

A pinhole camera with KITTI's intrinsics (scaled to the image size) 1.65 m above a road looks
down a street: road with lane markings, sidewalks, building facades with windows, trees, parked
and oncoming cars, poles, pedestrians, sky. Surfaces are axis-aligned boxes and the ground plane,
so every pixel's depth is exact (ray casting). Sunlight gives Lambertian shading and shadows cast
by every object onto the road; ``shadow=True`` adds a hard shadow band across the whole scene
(an overpass), the illumination change the paper's semantic branch is meant to be robust to.

Camera rays go through pixel centres, at integer pixel coordinates: the one pixel convention of
:mod:`semattnet.geometry.projection`. The sparse input comes from a simulated 64-beam spinning LiDAR
mounted 0.27 m behind and 0.08 m above the camera (so, as in KITTI, it sees a little behind foreground
edges): rays are cast from the sensor, 2 cm range noise, the returns (``SyntheticFrame.lidar_points``)
projected into the camera by :func:`semattnet.geometry.project_points`, ~5 % of pixels valid. The
ground truth keeps ~16 % of pixels of the exact depth below the LiDAR's top beam,
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

Domains (:mod:`.domain`, the ``domain`` argument of :func:`make_frame`): the rig and the look. ``"source"`` (the
default) is everything above, drawn exactly as it always was; ``"target"`` sees the same streets with another
car's sensors (a lower, tilted 32-beam LiDAR, a lower camera pitched down with a wider lens) under other light.

Modules, one concern each: :mod:`.layout` (the boxes of a street), :mod:`.domain` (rigs), :mod:`.raycast`
(exact ray casting, the camera's view), :mod:`.shading` (labels, colours, light), :mod:`.materials` (classes and LiDAR
materials), :mod:`.realistic` (the realistic style's dressing), :mod:`.lidar` (the LiDAR simulator);
this module puts a frame together.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semattnet._errors import InputError
from semattnet.data.io import quantize_depth
from semattnet.geometry.cameras import KITTI_IMAGE_SIZE, KITTI_K

from .domain import SOURCE, Domain, Pose, get_domain
from .layout import Box, make_boxes
from .lidar import MAX_RANGE, simulate_lidar
from .materials import CITYSCAPES_PALETTE, LABEL_COLOURS, MATERIAL_IDS, MATERIALS, surfaces
from .raycast import RayView, camera_view
from .realistic import Dress, camouflage_poles, decorate, dress
from .shading import albedo, labels, overpass, overpass_band, render, sun_direction, sunlight

__all__ = [
    "CITYSCAPES_PALETTE",
    "KITTI_K",
    "MATERIALS",
    "SCENE_STYLES",
    "Scene",
    "Shot",
    "SyntheticFrame",
    "check_style",
    "intrinsics",
    "make_frame",
    "make_scene",
    "shoot",
]

#: Scene styles of :func:`make_frame` (the first is the default).
SCENE_STYLES: tuple[str, ...] = ("ideal", "realistic")


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
    meta: dict[str, object] = field(default_factory=dict)
    #: (H, W) uint8 index into MATERIALS of the surface each pixel sees (all "matte" in the ideal style).
    material: np.ndarray | None = None
    #: (H, W) bool: road markings and posters of the realistic style (colour edges on flat surfaces).
    paint: np.ndarray | None = None
    #: (N, 3) float32 LiDAR returns in the LiDAR frame (x forward, y left, z up; metres, range noise included):
    #: ``sparse`` is ``project_points(lidar_points, K, T_cam_lidar, (W, H))`` in KITTI's 1/256 m steps.
    lidar_points: np.ndarray | None = None
    #: (4, 4) LiDAR -> camera transform of ``lidar_points``.
    T_cam_lidar: np.ndarray | None = None


def _intrinsics(height: int, width: int, size_of_kitti: bool) -> np.ndarray:
    """KITTI's intrinsics, scaled to KITTI's field of view at this width when ``size_of_kitti``."""
    K: np.ndarray = KITTI_K.copy()
    if size_of_kitti:
        kitti_w, kitti_h = KITTI_IMAGE_SIZE
        s = width / float(kitti_w)
        K[0, 0] = K[1, 1] = KITTI_K[0, 0] * s
        K[0, 2] = width / 2.0
        K[1, 2] = height - (kitti_h - KITTI_K[1, 2]) * s  # keep the horizon where KITTI has it
    return K


def intrinsics(height: int, width: int, size_of_kitti: bool = True, domain: Domain = SOURCE) -> np.ndarray:
    """The camera matrix of ``domain`` at this image size: KITTI's (scaled to KITTI's field of view at this width
    when ``size_of_kitti``), the focal length times ``domain.focal_scale``, the principal row where it says."""
    K = _intrinsics(height, width, size_of_kitti)
    if domain.focal_scale != 1.0:
        K[0, 0] *= domain.focal_scale
        K[1, 1] *= domain.focal_scale
    if domain.principal_row is not None:
        K[1, 2] = domain.principal_row * height
    return K


def _colours(
    view: RayView, labels: np.ndarray, boxes: list[Box], dress: Dress | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) albedo, (N,) material codes and (N,) paint mask, with the realistic style's glass, posters,
    markings and camouflage (the ideal style: all matte, no paint beyond the centre line)."""
    n = view.height * view.width
    if dress is None:
        return albedo(view, labels, boxes), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    hits = surfaces(view.points, view.idx, view.axis, boxes)
    colour, paint = decorate(view, labels, albedo(view, labels, boxes), hits, dress)
    return colour, np.where(view.far, MATERIAL_IDS["matte"], hits[0]), paint


def ground_truth_of(depth: np.ndarray, K: np.ndarray, rng: np.random.Generator, domain: Domain = SOURCE) -> np.ndarray:
    """~16 % of the pixels the LiDAR's field of view covers, exact depth, in range (0 elsewhere).

    The field of view starts at the first row whose pixel centre (integer v) lies below the top beam (2 deg up
    in the source domain; the top beam's elevation in the camera for others).
    """
    height, width = depth.shape
    top = domain.elevation[0] - domain.lidar_pitch + domain.camera_pitch
    top_row = int(np.clip(np.ceil(K[1, 2] - K[1, 1] * np.tan(np.deg2rad(top))), 0, height - 1))
    eligible = (depth > 0) & (depth < MAX_RANGE)
    eligible[:top_row] = False
    p = min(1.0, 0.17 * height * width / max(1, eligible.sum()))
    return np.where(eligible & (rng.random((height, width)) < p), depth, 0.0)


@dataclass
class Scene:
    """What a scene seed draws before any camera looks: the street, its dressing and its light."""

    boxes: list[Box]
    dressing: Dress | None
    sun: np.ndarray
    exposure: float
    shadow: bool
    band: tuple[float, float]  # the overpass's z range in the street frame ((0, 0): none)
    domain: Domain


def make_scene(rng: np.random.Generator, style: str, domain: Domain = SOURCE, shadow: bool | None = None) -> Scene:
    """The street (boxes, the ``style``'s dressing), the sun, the exposure and the overpass, drawn from ``rng``."""
    boxes, dressing = make_boxes(rng), None
    if style == "realistic":
        boxes, dressing = dress(rng, boxes)
    sun = sun_direction(rng, domain.sun_x, domain.sun_z)
    exposure = float(rng.uniform(*domain.exposure))
    shadow = bool(rng.random() < 0.5) if shadow is None else shadow
    band = overpass_band(rng) if shadow else (0.0, 0.0)
    if dressing is not None:
        camouflage_poles(boxes, dressing, sun)  # needs the sun; draws nothing
    return Scene(boxes, dressing, sun, exposure, shadow, band, domain)


@dataclass
class Shot:
    """One camera's picture of a scene: (H, W, 3) uint8 image, (H, W) labels, exact depth (float64 metres, 0 for
    sky), material codes and paint."""

    rgb: np.ndarray
    labels: np.ndarray
    depth: np.ndarray
    material: np.ndarray
    paint: np.ndarray


def shoot(scene: Scene, K: np.ndarray, size: tuple[int, int], pose: Pose, rng: np.random.Generator) -> Shot:
    """Render ``scene`` from a camera at ``pose`` (street frame) with intrinsics ``K``; the image noise from ``rng``."""
    height, width = size
    view = camera_view(K, height, width, scene.boxes, pose)
    label = labels(view, scene.boxes)
    light = sunlight(view, scene.boxes, scene.sun, scene.exposure)
    if scene.shadow:
        light = overpass(view, light, scene.band)
    colour, material, paint = _colours(view, label, scene.boxes, scene.dressing)
    if scene.domain.albedo_gain != SOURCE.albedo_gain:
        colour = colour * np.asarray(scene.domain.albedo_gain)
    rgb = render(view, colour, light, scene.exposure, rng, scene.domain.noise)
    return Shot(
        rgb,
        label.reshape(height, width),
        view.depth.reshape(height, width),
        material.astype(np.uint8).reshape(height, width),
        paint.reshape(height, width),
    )


def make_frame(
    height: int = 352,
    width: int = 1216,
    seed: int = 0,
    shadow: bool | None = None,
    size_of_kitti: bool = True,
    style: str = "ideal",
    domain: str | Domain = "source",
) -> SyntheticFrame:
    """Generate one scene, deterministic in ``seed`` (and ``style``, ``domain``).

    Args:
        height: image height (any; KITTI's raw frames are about 375 x 1242). width: image width.
        seed: random seed.
        shadow: add a hard shadow band across the scene (random, p = 0.5, when None).
        size_of_kitti: scale the intrinsics so the field of view is KITTI's at this width.
        style: one of :data:`SCENE_STYLES`: ``"ideal"`` (every surface returns LiDAR, colour edges are
            depth edges but for shadows) or ``"realistic"`` (see the module docstring).
        domain: the rig and look (:class:`~semattnet.synthetic.domain.Domain` or a name of
            :data:`~semattnet.synthetic.domain.DOMAINS`); ``"source"`` is the original generator's.

    Raises:
        InputError: unknown ``style`` or ``domain``.
    """
    check_style(style)
    dom = get_domain(domain)
    rng = np.random.default_rng(seed)  # every step below draws from it, in this order
    K = intrinsics(height, width, size_of_kitti, dom)
    scene = make_scene(rng, style, dom, shadow)
    shot = shoot(scene, K, (height, width), Pose.of_camera(dom), rng)
    scan = simulate_lidar(height, width, K, scene.boxes, rng, realistic=scene.dressing is not None, domain=dom)
    gt = ground_truth_of(shot.depth, K, rng, dom)
    meta = {
        "seed": seed,
        "style": style,
        "shadow_band_z": list(scene.band),
        "sun": scene.sun.tolist(),
        "exposure": scene.exposure,
    } | ({"domain": dom.name} if dom != SOURCE else {})
    if scene.dressing is not None:
        meta |= {**scene.dressing.meta, "lidar": scan.stats}
    return SyntheticFrame(
        rgb=shot.rgb,
        semantic=LABEL_COLOURS[shot.labels],
        sparse=quantize_depth(scan.sparse),
        gt=quantize_depth(gt),
        depth=shot.depth.astype(np.float32),
        labels=shot.labels,
        K=K,
        shadowed=scene.shadow,
        meta=meta,
        material=shot.material,
        paint=shot.paint,
        lidar_points=scan.points,
        T_cam_lidar=scan.T_cam_lidar,
    )


def check_style(style: str) -> None:
    """Raise :class:`~semattnet.InputError` unless ``style`` is one of :data:`SCENE_STYLES`."""
    if style not in SCENE_STYLES:
        raise InputError(f"style: unknown scene style {style!r}; expected one of {', '.join(SCENE_STYLES)}")
