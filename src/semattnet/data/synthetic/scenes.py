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

Modules, one concern each: :mod:`.layout` (the boxes of a street), :mod:`.raycast` (exact ray casting,
the camera's view), :mod:`.shading` (labels, colours, light), :mod:`.materials` (classes and LiDAR
materials), :mod:`.realistic` (the realistic style's dressing), :mod:`.lidar` (the LiDAR simulator);
this module puts a frame together.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from semattnet._errors import InputError
from semattnet.data.io import quantize_depth
from semattnet.geometry.cameras import KITTI_IMAGE_SIZE, KITTI_K

from .layout import Box, make_boxes
from .lidar import MAX_RANGE, T_CAM_LIDAR, simulate_lidar
from .materials import CITYSCAPES_PALETTE, LABEL_COLOURS, MATERIAL_IDS, MATERIALS, surfaces
from .raycast import View, camera_view
from .realistic import Dress, camouflage_poles, decorate, dress
from .shading import albedo, labels, overpass, render, sun_direction, sunlight

__all__ = ["CITYSCAPES_PALETTE", "KITTI_K", "MATERIALS", "SCENE_STYLES", "SyntheticFrame", "check_style", "make_frame"]

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


def _colours(
    view: View, labels: np.ndarray, boxes: list[Box], dress: Dress | None, sun: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) albedo, (N,) material codes and (N,) paint mask, with the realistic style's glass, posters,
    markings and camouflage (the ideal style: all matte, no paint beyond the centre line)."""
    n = view.height * view.width
    if dress is None:
        return albedo(view, labels, boxes), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=bool)
    camouflage_poles(boxes, dress, sun)  # needs the sun; draws nothing
    hits = surfaces(view.points, view.idx, view.axis, boxes)
    colour, paint = decorate(view, labels, albedo(view, labels, boxes), hits, dress)
    return colour, np.where(view.far, MATERIAL_IDS["matte"], hits[0]), paint


def _ground_truth(depth: np.ndarray, K: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """~16 % of the pixels the LiDAR's field of view covers, exact depth, in range (0 elsewhere).

    The field of view starts at the first row whose pixel centre (integer v) lies below the top beam (2 deg up).
    """
    height, width = depth.shape
    top_row = int(np.clip(np.ceil(K[1, 2] - K[1, 1] * np.tan(np.deg2rad(2.0))), 0, height - 1))
    eligible = (depth > 0) & (depth < MAX_RANGE)
    eligible[:top_row] = False
    p = min(1.0, 0.17 * height * width / max(1, eligible.sum()))
    return np.where(eligible & (rng.random((height, width)) < p), depth, 0.0)


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
        height: image height (any; KITTI's raw frames are about 375 x 1242). width: image width.
        seed: random seed.
        shadow: add a hard shadow band across the scene (random, p = 0.5, when None).
        size_of_kitti: scale the intrinsics so the field of view is KITTI's at this width.
        style: one of :data:`SCENE_STYLES`: ``"ideal"`` (every surface returns LiDAR, colour edges are
            depth edges but for shadows) or ``"realistic"`` (see the module docstring).

    Raises:
        InputError: unknown ``style``.
    """
    check_style(style)
    rng = np.random.default_rng(seed)  # every step below draws from it, in this order
    K = _intrinsics(height, width, size_of_kitti)
    boxes, dressing = make_boxes(rng), None
    if style == "realistic":
        boxes, dressing = dress(rng, boxes)
    view = camera_view(K, height, width, boxes)
    label = labels(view, boxes)
    sun = sun_direction(rng)
    exposure = rng.uniform(0.7, 1.15)
    light = sunlight(view, boxes, sun, exposure)
    shadow = bool(rng.random() < 0.5) if shadow is None else shadow
    band = (0.0, 0.0)
    if shadow:
        light, band = overpass(view, light, rng)
    colour, material, paint = _colours(view, label, boxes, dressing, sun)
    rgb = render(view, colour, light, exposure, rng)
    label = label.reshape(height, width)
    depth = np.where(view.far.reshape(height, width), 0.0, view.points[:, 2].reshape(height, width))
    scan = simulate_lidar(height, width, K, boxes, rng, realistic=dressing is not None)
    gt = _ground_truth(depth, K, rng)
    meta = {"seed": seed, "style": style, "shadow_band_z": list(band), "sun": sun.tolist(), "exposure": exposure}
    if dressing is not None:
        meta |= {**dressing.meta, "lidar": scan.stats}
    return SyntheticFrame(
        rgb=rgb,
        semantic=LABEL_COLOURS[label],
        sparse=quantize_depth(scan.sparse),
        gt=quantize_depth(gt),
        depth=depth.astype(np.float32),
        labels=label,
        K=K,
        shadowed=shadow,
        meta=meta,
        material=material.astype(np.uint8).reshape(height, width),
        paint=paint.reshape(height, width),
        lidar_points=scan.points,
        T_cam_lidar=T_CAM_LIDAR.copy(),
    )


def check_style(style: str) -> None:
    """Raise :class:`~semattnet.InputError` unless ``style`` is one of :data:`SCENE_STYLES`."""
    if style not in SCENE_STYLES:
        raise InputError(f"style: unknown scene style {style!r}; expected one of {', '.join(SCENE_STYLES)}")
