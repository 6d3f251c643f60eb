"""Pictures: colourised depth maps and per-branch panels (the paper's intermediate-depth figure)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

__all__ = ["DEPTH_CMAP", "DEPTH_MAX_M", "colorize_depth", "save_panel"]

#: Fixed scale of every depth picture: matplotlib's "turbo" from 0 to 80 m (KITTI's range);
#: pixels without depth (0) are black.
DEPTH_CMAP = "turbo"
DEPTH_MAX_M = 80.0


def colorize_depth(depth: np.ndarray, vmax: float = DEPTH_MAX_M, cmap: str = DEPTH_CMAP) -> np.ndarray:
    """(H, W) metres -> (H, W, 3) uint8 on a fixed scale [0, vmax]; invalid (<= 0) is black."""
    from matplotlib import colormaps

    d = np.asarray(depth, dtype=np.float32)
    rgb = colormaps[cmap](np.clip(d / vmax, 0.0, 1.0))[..., :3]
    rgb[~(d > 0)] = 0.0
    return (rgb * 255.0 + 0.5).astype(np.uint8)


def save_panel(tiles: Sequence[tuple[str, np.ndarray]], path: str | Path, columns: int = 1) -> Path:
    """Stack labelled (H, W, 3) uint8 tiles into one PNG (row-major, ``columns`` per row)."""
    if not tiles:
        raise ValueError("save_panel needs at least one tile")
    h, w = tiles[0][1].shape[:2]
    label_h = 14
    rows = (len(tiles) + columns - 1) // columns
    canvas = Image.new("RGB", (columns * w, rows * (h + label_h)), "white")
    draw = ImageDraw.Draw(canvas)
    for i, (label, tile) in enumerate(tiles):
        if tile.shape[:2] != (h, w):
            raise ValueError(f"tile {label!r} is {tile.shape[:2]}, expected {(h, w)}")
        x, y = (i % columns) * w, (i // columns) * (h + label_h)
        draw.text((x + 3, y + 1), label, fill="black")
        canvas.paste(Image.fromarray(tile), (x, y + label_h))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)
    return path
