"""A bird's-eye view of a point cloud: a NumPy rasteriser of the camera's x-z (ground) plane.

Camera frame: x right, y down, z forward (metres). The picture looks down from above with the camera at the
bottom centre: columns are x (left to right), rows are z (far at the top). Pixel rule: with cells of
``cw = (x1 - x0) / W`` by ``ch = (z1 - z0) / H`` metres, a point lands in column ``floor((x - x0) / cw)`` and row
``H - 1 - floor((z - z0) / ch)``; points outside the ranges are dropped. Where several points share a cell, the
highest one (smallest y) is drawn, as seen from above.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import InputError

if TYPE_CHECKING:
    from semattnet.geometry.projection import PointCloud

__all__ = ["birds_eye_view"]

#: Colour of the overlaid LiDAR scan (RGB).
LIDAR_COLOR = (255, 0, 255)


def _cells(
    xyz: np.ndarray, size: tuple[int, int], x_range: tuple[float, float], z_range: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, col, keep) of each point (module doc's pixel rule)."""
    h, w = size
    x, z = xyz[:, 0].astype(np.float64), xyz[:, 2].astype(np.float64)
    col = np.floor((x - x_range[0]) / ((x_range[1] - x_range[0]) / w)).astype(np.int64)
    row = h - 1 - np.floor((z - z_range[0]) / ((z_range[1] - z_range[0]) / h)).astype(np.int64)
    keep = np.isfinite(x) & np.isfinite(z) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    return row, col, keep


def _height_colors(y: np.ndarray, height_range: tuple[float, float]) -> np.ndarray:
    from matplotlib import colormaps

    lo, hi = height_range
    t = np.clip((-y - lo) / max(hi - lo, 1e-6), 0, 1)  # height above the camera is -y
    return (colormaps["viridis"](t)[:, :3] * 255 + 0.5).astype(np.uint8)


def _paint(
    canvas: np.ndarray,
    xyz: np.ndarray,
    colors: np.ndarray,
    x_range: tuple[float, float],
    z_range: tuple[float, float],
) -> None:
    row, col, keep = _cells(xyz, canvas.shape[:2], x_range, z_range)
    flat = row[keep] * canvas.shape[1] + col[keep]
    y, colors = xyz[keep, 1], colors[keep]
    order = np.lexsort((y, flat))  # by cell, then highest (smallest y) first
    flat, colors = flat[order], colors[order]
    first = np.ones(flat.shape, dtype=bool)
    first[1:] = flat[1:] != flat[:-1]
    canvas.reshape(-1, 3)[flat[first]] = colors[first]


def birds_eye_view(
    cloud: PointCloud | np.ndarray,
    size: tuple[int, int] = (400, 400),
    x_range: tuple[float, float] | None = None,
    z_range: tuple[float, float] = (0.0, 40.0),
    color: str = "rgb",
    lidar: np.ndarray | None = None,
    lidar_color: tuple[int, int, int] = LIDAR_COLOR,
    height_range: tuple[float, float] = (-2.0, 3.0),
    background: int = 0,
) -> np.ndarray:
    """Rasterise a cloud seen from above (module doc).

    Args:
        cloud: a :class:`semattnet.geometry.PointCloud` (camera frame) or an (N, 3) array of x, y, z metres.
        size: (height, width) pixels of the picture.
        x_range: (left, right) metres; None: centred on the camera with square cells (width * depth / height).
        z_range: (near, far) metres.
        color: "rgb" (the cloud's colours; falls back to height when it has none) or "height" (viridis over
            ``height_range`` metres above the camera).
        lidar: optional (N, 3|4) points in the same frame, drawn on top in ``lidar_color``.
        background: grey level of empty cells.

    Returns:
        (H, W, 3) uint8.
    """
    h, w = (int(s) for s in size)
    if h <= 0 or w <= 0:
        raise InputError(f"birds_eye_view: size must be positive (height, width), got {size}")
    if z_range[1] <= z_range[0]:
        raise InputError(f"birds_eye_view: z_range must be (near, far) with far > near, got {z_range}")
    if x_range is None:
        half = (z_range[1] - z_range[0]) * w / h / 2
        x_range = (-half, half)
    if x_range[1] <= x_range[0]:
        raise InputError(f"birds_eye_view: x_range must be (left, right) with right > left, got {x_range}")
    xyz = np.asarray(getattr(cloud, "xyz", cloud), dtype=np.float64)[:, :3]
    rgb = getattr(cloud, "rgb", None)
    if color not in ("rgb", "height"):
        raise InputError(f"birds_eye_view: color must be 'rgb' or 'height', got {color!r}")
    colors = np.asarray(rgb, dtype=np.uint8) if color == "rgb" and rgb is not None else None
    if colors is None:
        colors = _height_colors(xyz[:, 1], height_range)
    canvas = np.full((h, w, 3), background, dtype=np.uint8)
    if len(xyz):
        _paint(canvas, xyz, colors, x_range, z_range)
    if lidar is not None and len(lidar):
        pts = np.asarray(lidar, dtype=np.float64)[:, :3]
        row, col, keep = _cells(pts, (h, w), x_range, z_range)
        canvas[row[keep], col[keep]] = np.asarray(lidar_color, dtype=np.uint8)
    return canvas
