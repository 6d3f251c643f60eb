"""Depth pictures: a fixed colour scale for depth, KITTI-style error maps, fusion-weight images."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from semattnet._errors import InputError

__all__ = ["DEPTH_CMAP", "DEPTH_MAX_M", "colorize_depth", "confidence_image", "error_map", "write_depth_pictures"]

#: Fixed scale of every depth picture: matplotlib's "turbo" from 0 to 80 m (KITTI's range);
#: pixels without depth (0) are black.
DEPTH_CMAP = "turbo"
DEPTH_MAX_M = 80.0


@functools.cache
def _colour_table(cmap: str) -> np.ndarray:
    """(N, 3) uint8: the colormap's N colours, as :func:`colorize_depth` writes them."""
    from matplotlib import colormaps

    colours = colormaps[cmap]
    return (colours(np.arange(colours.N))[:, :3] * 255.0 + 0.5).astype(np.uint8)


def colorize_depth(depth: np.ndarray, vmax: float = DEPTH_MAX_M, cmap: str = DEPTH_CMAP) -> np.ndarray:
    """(H, W) metres -> (H, W, 3) uint8 on a fixed scale [0, vmax]; invalid (<= 0) is black.

    Each pixel is the colormap's colour ``floor(N * clip(d / vmax, 0, 1))`` (the last for ``d >= vmax``), looked
    up in its table of N uint8 colours: the picture matplotlib's colormap call gives, without its float image."""
    table = _colour_table(cmap)
    n = len(table)
    d = np.asarray(depth, dtype=np.float32)
    valid = d > 0
    x = np.clip(d / np.float32(vmax), 0.0, 1.0) * np.float32(n)
    index = np.where(valid, np.minimum(x, n - 1), 0).astype(np.intp)
    rgb = table[index]
    rgb[~valid] = 0
    return rgb


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


def write_depth_pictures(
    pred: Path, out: Path, gt: Path | None = None, vmax: float = DEPTH_MAX_M, overwrite: bool = False
) -> int:
    """Colourise a 16-bit depth PNG (or a folder of them) into ``out/NAME_color.png``, with
    ``out/NAME_error.png`` against ground truth ``gt`` (a file or a folder of same-named files).
    Returns the number of predictions drawn.

    Output policy: ``out`` may not be (inside) an input folder; existing pictures are replaced only
    with ``overwrite``; every input is read before anything is written and the pictures appear
    together (staged), so a corrupt file or a kill leaves ``out`` unchanged.
    """
    from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs, staged_outputs
    from semattnet.data.io import DataError, read_depth, write_image

    pred, out = Path(pred), Path(out)
    files = [pred] if pred.is_file() else sorted(pred.glob("*.png"))
    if not files:
        raise DataError(f"{pred}: no PNG predictions")
    if vmax <= 0 or not np.isfinite(vmax):
        raise InputError(f"vmax must be a finite positive depth in metres, got {vmax}")
    names = [f"{f.stem}{s}" for f in files for s in (("_color.png", "_error.png") if gt else ("_color.png",))]
    check_no_input_overlap([pred, gt], out_dir=out, out_files=[out / n for n in names])
    pictures = [Output("--out", out / n, "png") for n in names]  # --overwrite replaces pictures, nothing else
    check_outputs([("--pred", pred), ("--gt", gt)], [Output("--out", out, "folder"), *pictures], overwrite)

    def read(f: Path) -> tuple[np.ndarray, np.ndarray | None]:
        return read_depth(f), None if gt is None else read_depth(gt if Path(gt).is_file() else Path(gt) / f.name)

    for f in files:  # every input decodes before anything is written
        read(f)
    with staged_outputs(out, overwrite=overwrite) as stage:
        for f in files:
            d, g = read(f)
            write_image(stage / f"{f.stem}_color.png", colorize_depth(d, vmax))
            if g is not None:
                write_image(stage / f"{f.stem}_error.png", error_map(d, g))
    return len(files)
