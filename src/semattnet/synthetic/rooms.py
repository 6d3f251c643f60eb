"""Indoor rooms for the synthetic world, built of the streets' axis-aligned boxes so the same ray caster renders them.

A room spans x in [0, width], z in [0, depth] of the street frame (x right, y down, z forward, metres); its floor is
the caster's ground plane, its walls and ceiling boxes just outside (no sky). 3-15 items (:data:`ROOM_ITEMS`) stand
apart and :data:`KEEP_OUT` or more from the camera; the walls carry a door, 0-2 windows and 0-3 pictures. The
palette has no wall, floor or furniture, so each role maps to the class that plays its part in a street
(:data:`ROOM_CLASSES`): floor -> ``road``; walls, ceiling, door, windows, pictures -> ``building`` (the structure);
furniture bodies -> ``car`` (solid objects on the ground); legs and lamps -> ``pole``; leaves -> ``vegetation``.
Textures: planks, tiles, carpet, striped walls, skirting boards, wood grain, fabric, panelled doors, colour-block
pictures. Light: 1-3 ceiling lamps (Lambertian, distance fall-off), ambient light darker near walls and under furniture.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field

import numpy as np

from .domain import Pose, pitch_down
from .layout import CAM_HEIGHT, Box
from .materials import CLASS_IDS
from .raycast import RayView, camera_view
from .scenes import Shot
from .shading import render

__all__ = ["KEEP_OUT", "ROOM_CLASSES", "ROOM_ITEMS", "Finish", "Room", "make_room", "shoot_room", "yaw_pitch"]

Span = tuple[float, float]
Rect = tuple[float, float, float, float]
Size3 = tuple[float, float, float]
Rng = np.random.Generator

#: The class (a name of :data:`~.materials.CLASS_NAMES`) of each part's role.
ROOM_CLASSES: dict[str, str] = {
    "floor": "road",
    **dict.fromkeys(("wall", "ceiling", "door", "window", "picture"), "building"),
    "furniture": "car",
    **dict.fromkeys(("leg", "lamp"), "pole"),
    "plant": "vegetation",
}
#: Furniture: how often each is drawn, how often it stands against a wall, its width, depth and height ranges (m).
ROOM_ITEMS: dict[str, tuple[float, float, Span, Span, Span]] = {
    "table": (0.15, 0.0, (0.8, 2.0), (0.6, 1.1), (0.7, 0.78)),
    "chair": (0.18, 0.0, (0.42, 0.5), (0.42, 0.5), (0.8, 0.95)),
    "cabinet": (0.12, 1.0, (0.5, 2.0), (0.35, 0.6), (0.6, 2.1)),
    "shelf": (0.1, 1.0, (0.6, 1.6), (0.25, 0.4), (1.2, 2.2)),
    "bed": (0.06, 1.0, (0.9, 1.8), (1.9, 2.1), (0.9, 1.1)),
    "sofa": (0.08, 0.8, (1.4, 2.4), (0.8, 1.0), (0.75, 0.9)),
    "box": (0.15, 0.0, (0.25, 0.7), (0.25, 0.7), (0.2, 0.7)),
    "plant": (0.08, 0.5, (0.3, 0.45), (0.3, 0.45), (0.7, 1.6)),
    "lamp": (0.05, 0.0, (0.3, 0.4), (0.3, 0.4), (1.4, 1.75)),
}
#: Surface textures of the boxes (``Room.textures``).
TEXTURES: tuple[str, ...] = ("paint", "wall", "wood", "fabric", "door", "window", "picture")
#: No furniture within this distance (metres, on the floor) of the camera.
KEEP_OUT = 0.6


def yaw_pitch(yaw: float, pitch: float) -> np.ndarray:
    """(3, 3) rotation (street <- camera) of a camera turned ``yaw`` deg from +z towards +x, pitched ``pitch`` up."""
    c, s = np.cos(np.deg2rad(yaw)), np.sin(np.deg2rad(yaw))
    return np.asarray(np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]) @ pitch_down(-pitch))


@dataclass
class Finish:
    """How a room's surfaces look: the floor, the walls' stripes and skirting board, a table of random numbers."""

    floor: str  # "planks", "tiles" or "carpet"
    floor_albedo: np.ndarray  # (3,)
    floor_scale: float  # plank width or tile size, metres
    walls: tuple[float, float, float]  # stripes' period (m) and contrast (0: plain paint), skirting board height (m)
    table: np.ndarray  # (64, 3) in [0, 1): shades of planks and tiles, colours of picture cells


@dataclass
class Room:
    """A room: its boxes (with a texture each), its size, the camera in it, its lamps and its finish."""

    boxes: list[Box]
    textures: list[str]  # one of TEXTURES per box
    size: Size3  # width (x), depth (z), height, metres
    camera: Pose
    lamps: np.ndarray  # (L, 4): x, y, z (street frame) and power
    finish: Finish
    meta: dict[str, object] = field(default_factory=dict)


@dataclass
class _Placed:
    """A ``w`` x ``d`` footprint at (x, z), its back (v = 0) at high z, low z, low x or high x (``facing`` 0-3)."""

    x: float
    z: float
    w: float
    d: float
    facing: int

    def rect(self, u0: float, u1: float, v0: float, v1: float) -> Rect:
        """World (x0, x1, z0, z1) of the local rectangle u in [u0, u1] (across), v in [v0, v1] (out from the back)."""
        across = (u0, u1) if self.facing in (0, 2) else (self.w - u1, self.w - u0)
        out = (v0, v1) if self.facing in (1, 2) else (self.d - v1, self.d - v0)
        xs, zs = (across, out) if self.facing < 2 else (out, across)
        return self.x + xs[0], self.x + xs[1], self.z + zs[0], self.z + zs[1]


def _against(size: Size3, facing: int, s: float, w: float, d: float) -> _Placed:
    """A footprint ``w`` along the wall ``facing`` (0: z = D, 1: z = 0, 2: x = 0, 3: x = W) from ``s``, ``d`` deep."""
    x, z = ((s, size[1] - d), (s, 0.0), (0.0, s), (size[0] - d, s))[facing]
    return _Placed(x, z, w, d, facing)


class _Builder(list[tuple[Box, str]]):
    """Collects the boxes of a room, each with its texture."""

    def part(self, p: _Placed, role: str, uv: Rect, hs: Span, albedo: np.ndarray, texture: str = "paint") -> None:
        """A box over the rectangle ``uv`` (u0, u1, v0, v1) of ``p``'s footprint, ``hs`` metres above the floor."""
        x0, x1, z0, z1 = p.rect(*uv)
        lo, hi = np.array([x0, CAM_HEIGHT - hs[1], z0]), np.array([x1, CAM_HEIGHT - hs[0], z1])
        self.append((Box(lo, hi, ROOM_CLASSES[role], np.asarray(albedo, float)), texture))


def _build(kind: str, b: _Builder, p: _Placed, h: float, rng: Rng) -> None:
    """The boxes of a ``kind`` item standing at ``p``, ``h`` metres tall."""
    wood, fabric = rng.uniform([90, 55, 30], [210, 160, 110]), rng.uniform([40, 40, 45], [210, 190, 180])
    card = rng.uniform([150, 110, 70], [200, 160, 115])
    part, w, d = functools.partial(b.part, p), p.w, p.d
    if kind in ("table", "chair"):
        top = h - 0.04 if kind == "table" else rng.uniform(0.42, 0.47)
        part("furniture", (0, w, 0, d), (top - 0.04, top), wood, "wood")
        if kind == "chair":
            part("furniture", (0, w, 0, 0.05), (top, h), wood, "wood")
        for u, v in itertools.product((0.02, w - 0.07), (0.02, d - 0.07)):
            part("leg", (u, u + 0.05, v, v + 0.05), (0.0, top - 0.04), np.array([60.0, 55.0, 50.0]))
    elif kind == "cabinet":
        part("furniture", (0, w, 0, d), (0, h), wood, "wood" if rng.random() < 0.6 else "paint")
    elif kind == "box":
        part("furniture", (0, w, 0, d), (0, h), card)
        if rng.random() < 0.3:  # a smaller box on top
            part("furniture", (0.05, w * 0.7, 0.05, d * 0.7), (h, h + rng.uniform(0.15, 0.4)), card)
    elif kind == "shelf":
        _shelf(b, p, h, wood, rng)
    elif kind in ("bed", "sofa"):
        base, back = (0.5, 0.08) if kind == "bed" else (0.42, 0.22)
        part("furniture", (0, w, back, d), (0.0, base), fabric, "fabric")
        headboard, texture = (wood, "wood") if kind == "bed" else (fabric, "fabric")
        part("furniture", (0, w, 0, back), (0.0, h), headboard, texture)
        if kind == "bed":  # a pillow
            part("furniture", (0.1, w - 0.1, 0.12, 0.5), (base, base + 0.12), np.array([230.0, 228, 220]), "fabric")
        for u in (0.0, w - 0.18) if kind == "sofa" else ():  # arms
            part("furniture", (u, u + 0.18, back, d), (0.0, 0.62), fabric, "fabric")
    elif kind == "plant":
        pot = rng.uniform(0.25, 0.4)
        part("furniture", (0.05, w - 0.05, 0.05, d - 0.05), (0.0, pot), rng.uniform([140, 60, 40], [190, 110, 80]))
        part("plant", (0.0, w, 0.0, d), (pot, h), rng.uniform([30, 70, 20], [90, 140, 60]))
    else:  # a floor lamp
        part("lamp", (w / 2 - 0.02, w / 2 + 0.02, d / 2 - 0.02, d / 2 + 0.02), (0.0, h - 0.3), np.array([70.0, 70, 75]))
        part("lamp", (0.0, w, 0.0, d), (h - 0.3, h), rng.uniform([200, 180, 140], [250, 240, 210]))


def _shelf(b: _Builder, p: _Placed, h: float, wood: np.ndarray, rng: Rng) -> None:
    """An open shelf: back, sides and 3-5 boards, with boxes and books on the boards."""
    part, w, d, t = functools.partial(b.part, p), p.w, p.d, 0.02
    part("furniture", (0, w, 0, 0.01), (0, h), wood, "wood")
    for u in (0.0, w - t):
        part("furniture", (u, u + t, 0, d), (0, h), wood, "wood")
    levels = np.linspace(0.05, h - t, int(rng.integers(3, 6)))
    for level in levels:
        part("furniture", (t, w - t, 0, d), (level, level + t), wood, "wood")
    for lo, hi in itertools.pairwise(levels):
        u = t + rng.uniform(0, 0.2)
        while u < w - 0.2 and rng.random() < 0.8:
            size, top = rng.uniform(0.05, 0.35), lo + t + rng.uniform(0.4, 0.95) * (hi - lo - t)
            uv = (u, min(u + size, w - t), 0.01, d * rng.uniform(0.5, 0.95))
            part("furniture", uv, (lo + t, top), rng.uniform(30, 230, 3))
            u += size + rng.uniform(0.0, 0.3)


def _furnish(b: _Builder, size: Size3, camera: np.ndarray, taken: list[Rect], rng: Rng) -> list[str]:
    """Place 3-15 items (fewer where the room is full: 20 tries each): their kinds."""
    kinds, odds = list(ROOM_ITEMS), np.array([v[0] for v in ROOM_ITEMS.values()])
    placed: list[str] = []
    for _ in range(int(rng.integers(3, 16))):
        kind = kinds[int(rng.choice(len(kinds), p=odds / odds.sum()))]
        _, wall, (w0, w1), (d0, d1), (h0, h1) = ROOM_ITEMS[kind]
        w, d, h = rng.uniform(w0, w1), rng.uniform(d0, d1), min(rng.uniform(h0, h1), size[2] - 0.3)
        for _ in range(20):
            facing = int(rng.integers(4))
            if rng.random() < wall:
                p = _against(size, facing, rng.uniform(0, max((size[0] if facing < 2 else size[1]) - w, 0.0)), w, d)
            else:
                x_room, z_room = (size[0] - w, size[1] - d) if facing < 2 else (size[0] - d, size[1] - w)
                p = _Placed(rng.uniform(0, max(x_room, 0.0)), rng.uniform(0, max(z_room, 0.0)), w, d, facing)
            fp = p.rect(0, w, 0, d)
            near = np.hypot(np.clip(camera[0], fp[0], fp[1]) - camera[0], np.clip(camera[1], fp[2], fp[3]) - camera[1])
            inside = fp[0] >= 0 and fp[2] >= 0 and fp[1] <= size[0] and fp[3] <= size[1]
            apart = all(max(fp[0] - t[1], t[0] - fp[1], fp[2] - t[3], t[2] - fp[3]) > 0.05 for t in taken)
            if inside and apart and near >= KEEP_OUT:  # in the room, 5 cm from the others, clear of the camera
                taken.append(fp)
                _build(kind, b, p, h, rng)
                placed.append(kind)
                break
    return placed


def _frame(b: _Builder, wall: _Placed, role: str, u: Span, h: Span, colour: np.ndarray, bar: float = 0.06) -> None:
    """A frame of ``bar`` wide bars around the opening ``u`` x ``h`` on ``wall``; windows get a sill and a mullion."""
    (u0, u1), (h0, h1), mid = u, h, (u[0] + u[1]) / 2
    bars = [(u0 - bar, u0, h0, h1 + bar), (u1, u1 + bar, h0, h1 + bar), (u0, u1, h1, h1 + bar)]
    if role == "window":
        bars += [(u0, u1, h0 - bar, h0), (mid - bar / 2, mid + bar / 2, h0, h1)]
    for a, c, e, f in bars:
        b.part(wall, role, (a, c, 0, 0.06), (e, f), colour)


def _structure(b: _Builder, size: Size3, rng: Rng, taken: list[Rect]) -> dict[str, int]:
    """The walls (one paint, now and then an accent wall) and the ceiling: boxes 0-4; a door (the floor before it
    kept free), 0-2 windows and 0-3 pictures, on different walls."""
    W, D, H = size
    t, paint = 0.15, rng.uniform([150, 145, 135], [240, 238, 230])
    accent = int(rng.integers(4)) if rng.random() < 0.3 else -1
    walls = [_against(size, k, 0.0, W if k < 2 else D, 1.0) for k in range(4)]
    for k, wall in enumerate(walls):
        colour = rng.uniform(60, 230, 3) if k == accent else paint
        b.part(wall, "wall", (-t, wall.w + t, -t, 0.0), (0.0, H + t), colour, "wall")  # behind the wall's plane
    ceiling = rng.uniform([225, 225, 220], [250, 250, 248])
    b.part(_Placed(0.0, 0.0, D, W, 2), "ceiling", (-t, D + t, -t, W + t), (H, H + t), ceiling)
    order = [int(k) for k in rng.permutation(4)]
    frame = rng.uniform([200, 195, 185], [245, 245, 240]) if rng.random() < 0.6 else rng.uniform(60, 140, 3)
    wall, dw, dh = walls[order[0]], rng.uniform(0.8, 1.0), min(rng.uniform(2.0, 2.1), H - 0.2)
    s = rng.uniform(0.15, wall.w - dw - 0.15)
    b.part(wall, "door", (s, s + dw, 0, 0.03), (0.0, dh), rng.uniform([90, 60, 35], [230, 220, 210]), "door")
    _frame(b, wall, "door", (s, s + dw), (0.0, dh), frame)
    taken.append(wall.rect(s, s + dw, 0.0, 1.0))
    n_windows, n_pictures = int(rng.integers(0, 3)), int(rng.integers(0, 4))
    for k in range(n_windows + n_pictures):
        window, wall = k < n_windows, walls[order[1 + k % 3]]
        ww = rng.uniform(0.8, min(2.0, wall.w - 0.4)) if window else rng.uniform(0.3, 1.0)
        h0 = rng.uniform(0.8, 1.0) if window else rng.uniform(1.1, 1.5)
        h1 = min(h0 + (rng.uniform(1.1, 1.4) if window else rng.uniform(0.3, 0.8)), H - 0.15)
        s = rng.uniform(0.2, max(0.2, wall.w - ww - 0.2))
        kind = "window" if window else "picture"
        b.part(wall, kind, (s, s + ww, 0, 0.01 if window else 0.02), (h0, h1), rng.uniform(60, 230, 3), kind)
        if window:
            _frame(b, wall, "window", (s, s + ww), (h0, h1), frame)
    return {"windows": n_windows, "pictures": n_pictures, "door_wall": order[0]}


def _finish(rng: Rng) -> Finish:
    """The floor (planks, tiles or carpet: colour, scale, shades) and the walls' stripes."""
    floor = ("planks", "tiles", "carpet")[int(rng.choice(3, p=[0.45, 0.35, 0.2]))]
    scale = {"planks": rng.uniform(0.1, 0.25), "tiles": rng.uniform(0.3, 0.6), "carpet": 1.0}[floor]
    grey = rng.uniform(50, 235)  # planks: wood of this brightness; tiles and carpets: half saturated colours
    colour = grey * np.array([1.0, 0.75, 0.5]) if floor == "planks" else (rng.uniform(50, 235, 3) + grey) / 2
    contrast = float(rng.uniform(0.06, 0.15)) if rng.random() < 0.3 else 0.0
    walls = (float(rng.uniform(0.05, 0.4)), contrast, float(rng.uniform(0.06, 0.14)))
    return Finish(floor, colour, float(scale), walls, rng.random((64, 3)))


def make_room(rng: Rng) -> Room:
    """A random room 3-10 m wide and deep, 2.4-3.5 m high: walls, furniture, lamps, finish, and a camera in it 0.4-1.8 m
    above the floor, facing the room's centre +-60 deg, pitched -25..+10 deg (up)."""
    size = (float(rng.uniform(3, 10)), float(rng.uniform(3, 10)), float(rng.uniform(2.4, 3.5)))
    x, z = rng.uniform(0.5, size[0] - 0.5), rng.uniform(0.5, size[1] - 0.5)  # the camera: 0.5 m from the walls
    height, pitch = min(float(rng.uniform(0.4, 1.8)), size[2] - 0.3), float(rng.uniform(-25, 10))
    yaw = float(np.rad2deg(np.arctan2(size[0] / 2 - x, size[1] / 2 - z)) + rng.uniform(-60, 60))  # to the centre
    camera = Pose(np.array([x, CAM_HEIGHT - height, z]), yaw_pitch(yaw, pitch))
    meta: dict[str, object] = {"camera_height": float(height), "yaw": yaw, "pitch": pitch}
    b, taken = _Builder(), list[Rect]()
    meta |= _structure(b, size, rng, taken)
    items = _furnish(b, size, camera.position[[0, 2]], taken, rng)
    n = int(rng.integers(1, 4))
    lamps = np.stack([rng.uniform(0.5, size[0] - 0.5, n), CAM_HEIGHT - size[2] + rng.uniform(0.05, 0.3, n)], -1)
    lamps = np.column_stack((lamps, rng.uniform(0.5, size[1] - 0.5, n), rng.uniform(0.5, 1.0, n)))
    finish = _finish(rng)
    meta |= {"room_size": list(size), "items": items, "lamps": n, "floor": finish.floor, "boxes": len(b)}
    return Room([box for box, _ in b], [texture for _, texture in b], size, camera, lamps, finish, meta)


def _floor_albedo(room: Finish, points: np.ndarray) -> np.ndarray:
    """(N, 3) floor colours at ``points``: planks (staggered, seams), tiles (grout) or carpet."""
    x, z, s = points[:, 0], points[:, 2], room.floor_scale
    shade = 0.8 + 0.35 * room.table[:, 0]
    if room.floor == "planks":  # rows across x, 1.2 m boards staggered along z
        row = np.floor(x / s).astype(int)
        along = z / 1.2 + room.table[row % 64, 1]
        grain = 1.0 + 0.05 * np.sin(2 * np.pi * (x / 0.03 + 0.5 * np.sin(z * 2.0)))
        seam = (np.mod(x, s) < 0.006) | (np.mod(along, 1.0) < 0.005)
        factor = np.where(seam, 0.5, shade[(row * 7 + np.floor(along).astype(int) * 13) % 64] * grain)
    elif room.floor == "tiles":
        i, j = np.floor(x / s).astype(int), np.floor(z / s).astype(int)
        grout = (np.mod(x, s) < 0.008) | (np.mod(z, s) < 0.008)
        factor = np.where(grout, 0.7, shade[(i * 7 + j * 13) % 64] ** 0.5)
    else:
        factor = 0.95 + 0.05 * np.sin(x * 9.0) * np.sin(z * 7.0)
    out: np.ndarray = room.floor_albedo * factor[:, None]
    return out


def _box_albedo(room: Room, view: RayView, on: np.ndarray) -> np.ndarray:
    """(len(on), 3) colours of the box hits ``on``, by texture (see the module's docstring)."""
    idx, axis, p, fin = view.idx[on], view.axis[on], view.points[on], room.finish
    code = np.array([TEXTURES.index(t) for t in room.textures])[idx]
    at = {name: np.flatnonzero(code == k) for k, name in enumerate(TEXTURES)}
    out: np.ndarray = np.array([b.albedo for b in room.boxes], float)[idx]
    flat = axis == 1  # in-face coordinates: s across, t up (along z on flat faces)
    s, t = np.where(axis == 0, p[:, 2], p[:, 0]), np.where(flat, p[:, 2], CAM_HEIGHT - p[:, 1])
    k = at["wood"]
    out[k] *= 0.9 + 0.1 * np.sin(2 * np.pi * (t[k] / 0.035 + 0.6 * np.sin(2 * np.pi * s[k] / 0.8)))[:, None]
    k = at["fabric"]
    out[k] *= 0.92 + 0.08 * (np.sin(s[k] * 6.0) * np.sin(t[k] * 6.0))[:, None]
    k = at["wall"]
    out[k] *= np.where(np.mod(s[k], fin.walls[0]) < fin.walls[0] / 2, 1 - fin.walls[1], 1.0)[:, None]
    out[k[t[k] < fin.walls[2]]] = 232.0  # the skirting board
    k = np.concatenate((at["door"], at["window"], at["picture"]))  # patterns in the box face's own frame
    lo, hi = np.array([b.lo for b in room.boxes])[idx[k]], np.array([b.hi for b in room.boxes])[idx[k]]
    side = np.where(axis[k] == 0, 2, 0)[:, None]
    ds, ls = s[k] - np.take_along_axis(lo, side, 1)[:, 0], np.take_along_axis(hi - lo, side, 1)[:, 0]
    dt = t[k] - np.where(flat[k], lo[:, 2], CAM_HEIGHT - hi[:, 1])
    lt = np.maximum(np.where(flat[k], hi[:, 2] - lo[:, 2], hi[:, 1] - lo[:, 1]), 1e-6)
    door, window, picture = (code[k] == TEXTURES.index(name) for name in ("door", "window", "picture"))
    panel = door & (ds > 0.12) & (ds < ls - 0.12) & (dt > 0.15) & (dt < lt - 0.15) & (np.abs(dt - lt / 2) > 0.06)
    out[k[panel]] *= 0.85
    f = np.clip(dt / lt, 0, 1)[window, None]
    out[k[window]] = (1 - f) * np.array([110.0, 140.0, 95.0]) + f * np.array([215.0, 230.0, 250.0])
    cell = np.floor(3 * ds / np.maximum(ls, 1e-6)) + 3 * np.floor(3 * dt / lt) + 11 * idx[k]
    out[k[picture]] = 30 + 210 * fin.table[cell.astype(int)[picture] % 64]
    return out


def _light(room: Room, view: RayView, exposure: float) -> np.ndarray:
    """(N,) light: ``exposure`` x (ambient, less near walls and under furniture, + the lamps); windows glow."""
    n, p = view.height * view.width, view.points
    normal, on = np.zeros((n, 3)), np.flatnonzero(view.on_box)
    normal[view.ground] = [0.0, -1.0, 0.0]
    normal[on, view.axis[on]] = -np.sign(view.dirs[on, view.axis[on]])
    direct = np.zeros(n)
    for lx, ly, lz, power in room.lamps:
        vec = np.array([lx, ly, lz]) - p
        dist = np.maximum(np.linalg.norm(vec, axis=1), 1e-6)
        direct += power * np.clip(np.sum(normal * vec, 1) / dist, 0, 1) / (1 + (dist / 3.0) ** 2)
    ambient, g = np.full(n, 0.4), np.flatnonzero(view.ground)
    gx, gz = p[g, 0], p[g, 2]
    wall = np.maximum(np.minimum(np.minimum(gx, room.size[0] - gx), np.minimum(gz, room.size[1] - gz)), 0)
    ambient[g] *= 1 - 0.35 * np.exp(-wall / 0.25)
    under = np.zeros(len(g), dtype=bool)
    for box in room.boxes:
        if box.cls in ("car", "pole", "vegetation") and CAM_HEIGHT - box.hi[1] > 0.05:
            under |= (gx > box.lo[0]) & (gx < box.hi[0]) & (gz > box.lo[2]) & (gz < box.hi[2])
    direct[g[under]], ambient[g[under]] = 0.3 * direct[g[under]], 0.7 * ambient[g[under]]
    light: np.ndarray = exposure * (ambient + direct)
    light[(np.array([*room.textures, "paint"])[view.idx] == "window") & view.on_box] = 1.1 * exposure
    return light


def _view(room: Room, K: np.ndarray, height: int, width: int) -> RayView:
    """The camera's view of ``room``: the boxes inside that may be in view by :func:`~.raycast.camera_view`, the walls
    and the ceiling (boxes 0-4) here, as the inside of the room's box (cheaper than boxes all around the camera)."""
    lo, hi = np.array([b.lo for b in room.boxes[5:]]), np.array([b.hi for b in room.boxes[5:]])
    pick = np.array(list(itertools.product((False, True), repeat=3)))  # the 8 corners of each box, camera frame:
    corners = (np.where(pick, hi[:, None], lo[:, None]) - room.camera.position) @ room.camera.R
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    edges = np.array([[fx, 0, cx + 0.5], [-fx, 0, width - 0.5 - cx], [0, fy, cy + 0.5], [0, -fy, height - 0.5 - cy]])
    outside = corners @ np.vstack((edges, [0, 0, 1])).T - [0, 0, 0, 0, 0.1] < 0  # beyond an edge, behind the camera
    inner = 5 + np.flatnonzero(~np.any(np.all(outside, axis=1), axis=1))  # boxes not wholly beyond one of them
    view = camera_view(K, height, width, [room.boxes[i] for i in inner], room.camera)
    view.idx[view.on_box] = inner[view.idx[view.on_box]]
    o, d, (W, D, H) = room.camera.position, view.dirs, room.size
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = (np.where(d[:, 0] > 0, W, 0.0) - o[0]) / d[:, 0], (CAM_HEIGHT - H - o[1]) / d[:, 1]
        t = np.stack((x, y, (np.where(d[:, 2] > 0, D, 0.0) - o[2]) / d[:, 2]), 1)
    t[~(t > 0)] = np.inf
    axis, shell = np.argmin(t, 1), np.min(t, 1)
    near = shell < np.where(view.far, np.inf, view.depth)
    wall = np.select([axis == 0, axis == 2], [np.where(d[:, 0] > 0, 3, 2), np.where(d[:, 2] > 0, 0, 1)], 4)
    view.idx[near], view.axis[near], view.depth[near] = wall[near], axis[near], shell[near]
    view.points[near] = o + d[near] * shell[near, None]
    view.far[near], view.on_box[near], view.ground[near] = False, True, False
    return view


def shoot_room(
    room: Room, K: np.ndarray, size: tuple[int, int], rng: Rng, exposure: float, noise: float
) -> tuple[Shot, np.ndarray]:
    """Render ``room`` from its camera with intrinsics ``K`` at ``size`` (H, W), the image noise from ``rng``: the
    picture (all matte; windows and pictures are paint) and the (H, W) index of the box each pixel sees (-1: floor)."""
    height, width = size
    view = _view(room, K, height, width)
    box_cls = np.array([CLASS_IDS[b.cls] for b in room.boxes], dtype=np.int64)[np.maximum(view.idx, 0)]
    label = np.where(view.on_box, box_cls, np.where(view.ground, CLASS_IDS[ROOM_CLASSES["floor"]], CLASS_IDS["sky"]))
    colour, on = np.zeros((height * width, 3)), np.flatnonzero(view.on_box)
    colour[on] = _box_albedo(room, view, on)
    colour[view.ground] = _floor_albedo(room.finish, view.points[view.ground])
    rgb = render(view, colour, _light(room, view, exposure), exposure, rng, noise)
    paint = np.isin(np.array([*room.textures, "paint"])[view.idx], ("window", "picture")) & view.on_box
    label, depth, paint, surface = (a.reshape(height, width) for a in (label, view.depth, paint, view.idx))
    return Shot(rgb, label, depth, np.zeros((height, width), np.uint8), paint), surface
