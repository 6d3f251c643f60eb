"""Completing a user's frames from files to files: what ``semattnet predict`` does, for Python too."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from semattnet.data.io import clamp_for_png, read_depth, read_image, write_depth, write_image
from semattnet.data.pairing import FramePaths
from semattnet.inference.completer import Completion

__all__ = ["Completer", "complete_folder", "output_paths"]


class Completer(Protocol):
    """Anything called as ``completer(rgb, sparse, semantic)`` -> :class:`Completion`."""

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion: ...


def output_paths(frames: Sequence[FramePaths], out: Path) -> list[Path]:
    """The files :func:`complete_folder` always writes: ``NAME.png`` (16-bit depth) and ``NAME_color.png``."""
    return [out / f"{f.name}{suffix}" for f in frames for suffix in (".png", "_color.png")]


def _complete_one(
    completer: Completer, frame: FramePaths
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, Completion]:
    """Read one frame's files and complete it: (rgb, semantic, sparse, completion)."""
    image, lidar = read_image(frame.rgb), read_depth(frame.sparse)
    sem = read_image(frame.semantic) if frame.semantic is not None else None
    return image, sem, lidar, completer(image, lidar, sem)


def complete_folder(
    completer: Completer,
    frames: Sequence[FramePaths],
    out: str | Path,
    *,
    npy: bool = False,
    panel: bool = False,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Complete ``frames`` (see :func:`semattnet.data.pairing.pair_frames`) and write, per frame,
    ``NAME.png`` (KITTI 16-bit depth), ``NAME_color.png`` and optionally ``NAME.npy`` (float32
    metres) and ``NAME_panel.png`` (per-branch panel) into ``out``.

    Raises:
        FileExistsError: an output exists and ``overwrite`` is not set (checked before any work).
    """
    from semattnet.viz.depth import colorize_depth
    from semattnet.viz.panels import branch_panel

    out = Path(out)
    existing = [p for p in output_paths(frames, out) if p.exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{len(existing)} output(s) exist, e.g. {existing[0]}; pass --overwrite")
    written = []
    for frame in frames:
        image, sem, lidar, result = _complete_one(completer, frame)
        depth = clamp_for_png(result.depth, frame.name)
        written.append(write_depth(out / f"{frame.name}.png", depth, overwrite=True))
        write_image(out / f"{frame.name}_color.png", colorize_depth(depth), overwrite=True)
        if npy:
            np.save(out / f"{frame.name}.npy", result.depth.astype(np.float32))
        if panel:
            branch_panel(out / f"{frame.name}_panel.png", image, sem, lidar, result.outputs)
        log(f"{frame.name}: {result.depth.shape[1]}x{result.depth.shape[0]} -> {out / (frame.name + '.png')}")
    return written
