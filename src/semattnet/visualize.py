"""Pictures: colourised depth maps and per-branch panels (the paper's intermediate-depth figure)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

__all__ = [
    "DEPTH_CMAP",
    "DEPTH_MAX_M",
    "branch_panel",
    "colorize_depth",
    "confidence_image",
    "error_map",
    "plot_training_curves",
    "save_panel",
]

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


def plot_training_curves(csv_path: str | Path, out_path: str | Path) -> Path | None:
    """Training loss and validation RMSE against steps, from a run's ``log.csv``."""
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader(open(csv_path))) if Path(csv_path).exists() else []
    if not rows:
        return None
    train = [(int(r["step"]), float(r["loss"])) for r in rows if r["split"] == "train" and r["loss"]]
    val = [(int(r["step"]), float(r["rmse_mm"])) for r in rows if r["split"] != "train" and r["rmse_mm"]]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    if train:
        ax.plot(*zip(*train, strict=True), label="training loss (m²)", color="tab:blue")
        ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    if val:
        ax2 = ax.twinx()
        ax2.plot(*zip(*val, strict=True), "o-", label="validation RMSE (mm)", color="tab:red")
        ax2.set_ylabel("RMSE (mm)")
        ax2.legend(loc="upper center")
    ax.legend(loc="upper right")
    fig.tight_layout()
    out_path = Path(out_path)
    fig.savefig(out_path, dpi=100)
    plt.close(fig)
    return out_path


def error_map(pred: np.ndarray, gt: np.ndarray, abs_m: float = 3.0, rel: float = 0.05) -> np.ndarray:
    """KITTI-style error image: error normalised by min(|e| / abs_m, |e| / gt / rel) in 10 log2
    bins from 1/16 to 16, on ColorBrewer RdYlBu (blue = good, red = bad, KITTI's palette);
    pixels without ground truth are black. Returns (H, W, 3) uint8."""
    from matplotlib import colormaps

    gt = np.asarray(gt, dtype=np.float64)
    err = np.abs(np.asarray(pred, dtype=np.float64) - gt)
    valid = gt > 0
    norm = np.where(valid, np.minimum(err / abs_m, err / np.where(valid, gt, 1.0) / rel), 0.0)
    bins = np.clip(np.floor(np.log2(np.maximum(norm, 1e-12))) + 5, 0, 9).astype(int)  # [0,1/16) -> 0 ... [16,inf) -> 9
    colours = (colormaps["RdYlBu_r"].resampled(10)(np.arange(10))[:, :3] * 255 + 0.5).astype(np.uint8)
    out = colours[bins]
    out[~valid] = 0
    return out


def confidence_image(conf: np.ndarray) -> np.ndarray:
    """A fusion weight in [0, 1] as (H, W, 3) uint8 on matplotlib's "viridis"."""
    from matplotlib import colormaps

    return (colormaps["viridis"](np.clip(conf, 0, 1))[..., :3] * 255 + 0.5).astype(np.uint8)


def branch_panel(
    path: str | Path,
    rgb: np.ndarray,
    semantic: np.ndarray | None,
    sparse: np.ndarray,
    outputs: dict[str, np.ndarray],
    gt: np.ndarray | None = None,
    columns: int = 1,
) -> Path:
    """The paper's intermediate-depth figure for one frame: inputs, ground truth, CG / SG / DG,
    fused and refined depths, the three fusion weights and (with ground truth) the error map."""
    tiles: list[tuple[str, np.ndarray]] = [("RGB", np.asarray(rgb, dtype=np.uint8))]
    if semantic is not None:
        tiles.append(("semantic", np.asarray(semantic, dtype=np.uint8)))
    tiles.append(("sparse LiDAR", colorize_depth(sparse)))
    if gt is not None:
        tiles.append(("ground truth", colorize_depth(gt)))
    for key, label in (("color_depth", "CG depth"), ("semantic_depth", "SG depth"), ("guided_depth", "DG depth"),
                       ("fused_depth", "fused depth"), ("refined_depth", "refined depth")):  # fmt: skip
        if key in outputs:
            tiles.append((label, colorize_depth(outputs[key])))
    for key, label in (("color_conf", "CG weight"), ("semantic_conf", "SG weight"), ("guided_conf", "DG weight")):
        if key in outputs:
            tiles.append((label, confidence_image(outputs[key])))
    if gt is not None:
        final = outputs.get("refined_depth", outputs.get("fused_depth"))
        if final is not None:
            tiles.append(("error (KITTI colours)", error_map(final, gt)))
    return save_panel(tiles, path, columns=columns)
