"""The street a synthetic scene is built of: axis-aligned boxes on a ground plane (camera frame).

Camera frame: x right, y down, z forward, metres; the camera sits :data:`CAM_HEIGHT` above the ground
plane ``y = CAM_HEIGHT``. Road, sidewalks, building facades (with a grid of windows), trees, parked and
oncoming cars, poles and pedestrians; the street ends in a facade, so depth stays within ~100 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CAM_HEIGHT", "Box", "make_boxes", "road_half_width", "window_corners"]

#: Height of the camera above the ground plane, metres (KITTI's camera 02: 1.65 m).
CAM_HEIGHT = 1.65


@dataclass
class Box:
    """One axis-aligned box of the scene (camera frame, metres)."""

    lo: np.ndarray
    hi: np.ndarray
    cls: str
    albedo: np.ndarray
    material: str = "matte"  # a name in MATERIALS; "glass" boxes are car cabins (glass but for the roof)
    group: int = -1  # boxes of one car share a group
    poster: tuple[float, ...] | None = None  # see semattnet.synthetic.realistic


def _add(boxes: list[Box], lo: list[float], hi: list[float], cls: str, albedo: object) -> None:
    boxes.append(Box(np.asarray(lo, float), np.asarray(hi, float), cls, np.asarray(albedo, float)))


def _street_sides(rng: np.random.Generator, boxes: list[Box], road_half: float, walk: float) -> None:
    """Buildings and trees along both sides, then the facade closing the street."""
    for side in (-1, 1):
        z = rng.uniform(-2, 6)
        while z < 90:
            length = rng.uniform(6, 22)
            inner = side * (road_half + walk + rng.uniform(0, 1.5))
            x0, x1 = sorted((inner, inner + side * rng.uniform(5, 12)))
            if rng.random() < 0.25:  # a tree: trunk and crown
                cx = inner + side * 1.5
                _add(boxes, [cx - 0.2, -2.5, z + 2], [cx + 0.2, CAM_HEIGHT, z + 2.4], "vegetation", [70, 55, 40])
                _add(
                    boxes,
                    [cx - 2, -6.5, z],
                    [cx + 2, -2.5, z + 4.4],
                    "vegetation",
                    rng.uniform([40, 80, 20], [80, 130, 50]),
                )
            else:
                height = rng.uniform(5, 18)
                _add(
                    boxes,
                    [x0, CAM_HEIGHT - height, z],
                    [x1, CAM_HEIGHT, z + length],
                    "building",
                    rng.uniform([110, 90, 70], [200, 170, 150]),
                )
            z += length + rng.uniform(0, 5)
    end = rng.uniform(70, 100)  # the street ends in a facade, so depth stays within ~100 m
    _add(
        boxes,
        [-60, CAM_HEIGHT - rng.uniform(8, 20), end],
        [60, CAM_HEIGHT, end + 5],
        "building",
        rng.uniform([110, 90, 70], [200, 170, 150]),
    )


def _street_objects(rng: np.random.Generator, boxes: list[Box], road_half: float, walk: float) -> None:
    """Cars in lanes and at the kerb, poles at the kerb, pedestrians on the sidewalk."""
    for _ in range(int(rng.integers(2, 7))):
        lane = rng.choice([-1, 1]) * rng.choice([road_half - 1.2, road_half / 3])
        z = rng.uniform(5, 55)
        w, h, length = rng.uniform(1.6, 2.0), rng.uniform(1.3, 1.7), rng.uniform(3.8, 4.8)
        _add(
            boxes,
            [lane - w / 2, CAM_HEIGHT - h, z],
            [lane + w / 2, CAM_HEIGHT, z + length],
            "car",
            rng.uniform([20, 20, 20], [220, 220, 220]),
        )
    for _ in range(int(rng.integers(1, 5))):
        x, z = rng.choice([-1, 1]) * (road_half + 0.4), rng.uniform(4, 50)
        _add(boxes, [x - 0.08, CAM_HEIGHT - 5.5, z], [x + 0.08, CAM_HEIGHT, z + 0.16], "pole", [120, 120, 125])
    for _ in range(int(rng.integers(0, 5))):
        x, z = rng.choice([-1, 1]) * (road_half + rng.uniform(0.5, walk)), rng.uniform(4, 35)
        _add(
            boxes,
            [x - 0.25, CAM_HEIGHT - rng.uniform(1.5, 1.9), z],
            [x + 0.25, CAM_HEIGHT, z + 0.4],
            "person",
            rng.uniform([40, 30, 30], [200, 160, 160]),
        )


def make_boxes(rng: np.random.Generator) -> list[Box]:
    """A random street (the first draws of a frame's generator)."""
    boxes: list[Box] = []
    road_half = rng.uniform(3.5, 6.0)
    walk = rng.uniform(2.0, 3.5)
    _street_sides(rng, boxes, road_half, walk)
    _street_objects(rng, boxes, road_half, walk)
    return boxes


def road_half_width(boxes: list[Box]) -> float:
    """Half the road's width, from the poles at the kerb (5 m without poles)."""
    poles = [abs(b.lo[0]) for b in boxes if b.cls == "pole"]
    return min(poles) - 0.4 if poles else 5.0


def window_corners(points: np.ndarray) -> np.ndarray:
    """Which points (N, 3) of a facade lie on a window (a grid of 1.2 x 1.2 m panes)."""
    wy, wz = np.mod(points[:, 1], 3.0), np.mod(points[:, 2] + points[:, 0], 2.5)
    on: np.ndarray = (wy > 1.2) & (wy < 2.4) & (wz > 0.6) & (wz < 1.8)
    return on
