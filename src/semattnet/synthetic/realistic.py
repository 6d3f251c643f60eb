"""The realistic style's scene dressing, drawn right after the boxes from the frame's generator.

Cars split into a body and a glass cabin, some painted dark or glossy; one kerb-side car and the facades
behind it painted the same grey (p = 0.5); posters on facades; half the poles coloured like the facade
behind them; road markings (dashed edge lines, zebra crossings, stop lines, arrows). The LiDAR side of
the style (what dark paint, gloss and glass do to the beams) is in :mod:`.lidar`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .layout import CAM_HEIGHT, Box, road_half_width
from .materials import CLASS_IDS, MATERIAL_IDS
from .raycast import RayView

__all__ = ["Dress", "camouflage_poles", "decorate", "dress"]

#: Share of cars with dark paint (few LiDAR returns) and with glossy paint (specular wrong returns).
_DARK_SHARE, _GLOSSY_SHARE = 0.2, 0.2
_GLASS_RGB = np.array([38.0, 52.0, 72.0])  # dark bluish glass
_MARKING_RGB = np.array([235.0, 235.0, 230.0])


@dataclass
class Dress:
    """What the realistic style adds besides boxes: road markings, poles to colour like a facade, counts."""

    road_half: float
    markings: dict[str, Any]
    camo_poles: list[tuple[int, int]]  # (pole box, building box) to look alike under the sun
    meta: dict[str, Any]


def _dress_cars(rng: np.random.Generator, boxes: list[Box]) -> list[Box]:
    """Split every car into a body and a glass cabin; paint a share dark or glossy (the rest at least mid-grey)."""
    out: list[Box] = []
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
        out.append(Box(np.array([b.lo[0], belt, b.lo[2]]), b.hi.copy(), "car", albedo, material, g))
        out.append(Box(cabin_lo, cabin_hi, "car", albedo, "glass", g))
        g += 1
    return out


def _camouflage_car(rng: np.random.Generator, boxes: list[Box], road_half: float) -> float:
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


def _dress_facades(rng: np.random.Generator, boxes: list[Box], road_half: float, grey_side: float) -> int:
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
        bottom = CAM_HEIGHT - rng.uniform(0.3, 2.0)
        kind, period = int(rng.integers(3)), rng.uniform(0.25, 0.8)
        bright, dark = rng.uniform(170, 250, 3), rng.uniform(10, 70, 3)
        b.poster = (axis, s0, s0 + width, bottom - tall, bottom, kind, period, *bright, *dark)
        n += 1
    return n


def _camo_poles(rng: np.random.Generator, boxes: list[Box]) -> list[tuple[int, int]]:
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


def dress(rng: np.random.Generator, boxes: list[Box]) -> tuple[list[Box], Dress]:
    """Everything the realistic style draws about the scene, right after :func:`~.layout.make_boxes`."""
    road_half = road_half_width(boxes)
    boxes = _dress_cars(rng, boxes)
    grey_side = _camouflage_car(rng, boxes, road_half)
    posters = _dress_facades(rng, boxes, road_half, grey_side)
    poles = _camo_poles(rng, boxes)
    markings = _markings(rng)
    bodies = [b.material for b in boxes if b.cls == "car" and b.material != "glass"]
    cars = {"cars": len(bodies), "dark": bodies.count("dark"), "glossy": bodies.count("glossy")}
    meta = {
        "cars": {**cars, "camouflaged": int(grey_side != 0)},
        "posters": posters,
        "camouflaged_poles": len(poles),
        "markings": markings,
    }
    return boxes, Dress(road_half, markings, poles, meta)


def camouflage_poles(boxes: list[Box], dress: Dress, sun: np.ndarray) -> None:
    """Colour the chosen poles so their front face renders as the facade behind (same albedo x sunlight)."""
    for p, b in dress.camo_poles:
        side = np.sign(boxes[p].lo[0] + boxes[p].hi[0])
        facade = 0.45 + 0.75 * np.clip(-(np.array([-side, 0.0, 0.0]) @ sun), 0, 1)
        front = 0.45 + 0.75 * np.clip(-(np.array([0.0, 0.0, -1.0]) @ sun), 0, 1)
        boxes[p].albedo = boxes[b].albedo * facade / front


def _road_markings(points: np.ndarray, road: np.ndarray, dress: Dress) -> np.ndarray:
    """Which road points carry paint (the realistic markings; the centre line is :func:`~.shading.albedo`'s)."""
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


def decorate(
    view: RayView, labels: np.ndarray, albedo: np.ndarray, surfaces: tuple[np.ndarray, ...], dress: Dress
) -> tuple[np.ndarray, np.ndarray]:
    """Realistic albedo (glass dark bluish, posters, road markings) and where paint lies (no depth edges)."""
    material, poster, colour = surfaces
    albedo = albedo.copy()
    albedo[material == MATERIAL_IDS["glass"]] = _GLASS_RGB
    albedo[poster] = colour[poster]
    marking = _road_markings(view.points, labels == CLASS_IDS["road"], dress)
    albedo[marking] = _MARKING_RGB
    return albedo, poster | marking
