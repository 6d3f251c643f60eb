"""Panels: labelled tiles in one picture, and the per-branch panel (the paper's intermediate-depth figure)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image, ImageDraw

from semattnet._errors import InputError

if TYPE_CHECKING:
    from semattnet.geometry.calibration import RigCalibration
    from semattnet.geometry.projection import PointCloud
from semattnet.viz.depth import colorize_depth, confidence_image, error_map

__all__ = ["birds_eye_tile", "branch_panel", "save_panel"]


def save_panel(tiles: Sequence[tuple[str, np.ndarray]], path: str | Path, columns: int = 1) -> Path:
    """Stack labelled (H, W, 3) uint8 tiles into one PNG (row-major, ``columns`` per row)."""
    if not tiles:
        raise InputError("save_panel: needs at least one tile, got none")
    h, w = tiles[0][1].shape[:2]
    label_h = 14
    rows = (len(tiles) + columns - 1) // columns
    canvas = Image.new("RGB", (columns * w, rows * (h + label_h)), "white")
    draw = ImageDraw.Draw(canvas)
    for i, (label, tile) in enumerate(tiles):
        if tile.shape[:2] != (h, w):
            raise InputError(f"save_panel: tile {label!r} is {tile.shape[:2]}, expected {(h, w)}")
        x, y = (i % columns) * w, (i // columns) * (h + label_h)
        draw.text((x + 3, y + 1), label, fill="black")
        canvas.paste(Image.fromarray(tile), (x, y + label_h))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)
    return path


def branch_panel(
    path: str | Path,
    rgb: np.ndarray,
    semantic: np.ndarray | None,
    sparse: np.ndarray,
    outputs: dict[str, np.ndarray],
    gt: np.ndarray | None = None,
    columns: int = 1,
    extra: Sequence[tuple[str, np.ndarray]] = (),
) -> Path:
    """The paper's intermediate-depth figure for one frame: inputs, ground truth, CG / SG / DG,
    fused and refined depths, the three fusion weights, (with ground truth) the error map, then the
    ``extra`` labelled (H, W, 3) uint8 tiles (e.g. a bird's-eye view of the prediction)."""
    tiles: list[tuple[str, np.ndarray]] = [("RGB", np.asarray(rgb, dtype=np.uint8))]
    if semantic is not None:
        tiles.append(("semantic", np.asarray(semantic, dtype=np.uint8)))
    tiles.append(("sparse LiDAR", colorize_depth(sparse)))
    if gt is not None:
        tiles.append(("ground truth", colorize_depth(gt)))
    for key, label in (
        ("color_depth", "CG depth"),
        ("semantic_depth", "SG depth"),
        ("guided_depth", "DG depth"),
        ("fused_depth", "fused depth"),
        ("refined_depth", "refined depth"),
    ):
        if key in outputs:
            tiles.append((label, colorize_depth(outputs[key])))
    for key, label in (("color_conf", "CG weight"), ("semantic_conf", "SG weight"), ("guided_conf", "DG weight")):
        if key in outputs:
            tiles.append((label, confidence_image(outputs[key])))
    if gt is not None:
        final = outputs.get("refined_depth", outputs.get("fused_depth"))
        if final is not None:
            tiles.append(("error (KITTI colours)", error_map(final, gt)))
    tiles.extend((label, np.asarray(tile, dtype=np.uint8)) for label, tile in extra)
    return save_panel(tiles, path, columns=columns)


def birds_eye_tile(
    cloud: PointCloud, points: np.ndarray, calib: RigCalibration, shape: tuple[int, int], max_depth: float
) -> np.ndarray:
    """A square bird's-eye view of ``cloud`` (ahead up to min(max_depth, 50) m) centred in an (H, W) tile, with
    the LiDAR ``points`` (LiDAR frame) that land in the image overlaid: in front of the camera and in a pixel
    by :func:`semattnet.geometry.projection.pixel_indices` (the projection's own rule)."""
    from semattnet.geometry import points_to_pixels, transform_points
    from semattnet.geometry.projection import pixel_indices
    from semattnet.viz.pointcloud import birds_eye_view

    uv, z = points_to_pixels(points, calib.K, calib.T_cam_lidar)
    size = calib.image_size if calib.image_size is not None else (shape[1], shape[0])
    seen = (z > 0.1) & pixel_indices(uv, size)[2]
    lidar = transform_points(calib.T_cam_lidar, np.asarray(points[seen, :3], dtype=np.float64))
    far = float(min(max_depth, 50.0))
    side = min(shape)
    bev = birds_eye_view(cloud, size=(side, side), x_range=(-far / 2, far / 2), z_range=(0.0, far), lidar=lidar)
    tile = np.zeros((*shape, 3), dtype=np.uint8)
    top, left = (shape[0] - side) // 2, (shape[1] - side) // 2
    tile[top : top + side, left : left + side] = bev
    return tile
