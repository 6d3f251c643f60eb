"""Completing a user's frames from files to files: what ``semattnet predict`` does, for Python too."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from semattnet._utils.atomic import atomic_path
from semattnet._utils.outputs import OutputError, check_no_input_overlap, refuse_existing
from semattnet.data.io import clamp_for_png, read_depth, read_image, read_semantic, write_depth, write_image
from semattnet.data.pairing import FramePaths
from semattnet.inference.completer import Completion
from semattnet.inference.sharding import agree, on_main, process_group, rank_log, shard, shared_stage

__all__ = ["Completer", "check_frames", "complete_folder", "output_paths"]


class Completer(Protocol):
    """Anything called as ``completer(rgb, sparse, semantic)`` -> :class:`Completion`."""

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion: ...


def output_paths(frames: Sequence[FramePaths], out: Path, npy: bool = False, panel: bool = False) -> list[Path]:
    """The files :func:`complete_folder` writes: ``NAME.png`` (16-bit depth) and ``NAME_color.png``,
    with ``NAME.npy`` / ``NAME_panel.png`` when asked."""
    suffixes = (".png", "_color.png") + ((".npy",) if npy else ()) + (("_panel.png",) if panel else ())
    return [out / f"{f.name}{suffix}" for f in frames for suffix in suffixes]


def _read_frame(frame: FramePaths) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """One frame's (rgb, semantic, sparse); semantic maps are checked against the palette."""
    image, lidar = read_image(frame.rgb), read_depth(frame.sparse)
    sem = read_semantic(frame.semantic) if frame.semantic is not None else None
    return image, sem, lidar


def check_frames(frames: Sequence[FramePaths]) -> None:
    """Decode every input of every frame (raising :class:`DataError` / ``UnknownColorError`` naming
    the file) before anything is written."""
    for frame in frames:
        _read_frame(frame)


def complete_folder(
    completer: Completer,
    frames: Sequence[FramePaths],
    out: str | Path,
    *,
    npy: bool = False,
    panel: bool = False,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
    inputs: Sequence[str | Path | None] | None = None,
) -> list[Path]:
    """Complete ``frames`` (see :func:`semattnet.data.pairing.pair_frames`) and write, per frame,
    ``NAME.png`` (KITTI 16-bit depth), ``NAME_color.png`` and optionally ``NAME.npy`` (float32
    metres) and ``NAME_panel.png`` (per-branch panel) into ``out``.

    The output policy (:mod:`semattnet._utils.outputs`): ``out`` may not be (inside) an input folder;
    every input is decoded before any work; outputs are staged and appear only when all frames
    succeeded, so a corrupt frame or a kill leaves ``out`` unchanged.

    ``inputs``: the paths the user gave (files or folders; ``predict`` passes --rgb/--sparse/--semantic):
    ``out`` may not be one of these folders or inside one. ``out`` may never be the folder of an input
    file, and no output may resolve to an input file.

    Under ``torchrun`` (same arguments on every rank) the frames are split over the processes and
    the files are those of one process (:mod:`semattnet.inference.sharding`).

    Raises:
        FileExistsError: an output exists and ``overwrite`` is not set (checked before any work).
        OutputError: ``out`` is an input folder or inside one.
    """
    out = Path(out)
    outputs = output_paths(frames, out, npy, panel)
    with process_group():
        on_main(_check_outputs, frames, out, outputs, inputs, overwrite)
        mine = shard(frames)
        agree(check_frames, mine)
        log = rank_log(log)
        with shared_stage(out, overwrite, [p.relative_to(out) for p in outputs]) as stage:
            for frame in mine:
                h, w = _write_frame(completer, frame, stage, npy, panel)
                log(f"{frame.name}: {w}x{h} -> {out / (frame.name + '.png')}")
    return [out / f"{f.name}.png" for f in frames]


def _check_outputs(frames: Sequence[FramePaths], out: Path, outputs: list[Path],
                   inputs: Sequence[str | Path | None] | None, overwrite: bool) -> None:  # fmt: skip
    """Before any work: no output in or over an input, none existing unless ``overwrite``."""
    files = [Path(p) for f in frames for p in (f.rgb, f.sparse, f.semantic) if p is not None]
    check_no_input_overlap([*files, *(inputs or ())], out_dir=out, out_files=outputs)
    if out.resolve() in {p.resolve().parent for p in files}:
        raise OutputError(f"output folder {out} holds input frames; choose an --out outside the inputs")
    refuse_existing(outputs, overwrite)


def _write_frame(completer: Completer, frame: FramePaths, stage: Path, npy: bool, panel: bool) -> tuple[int, int]:
    """Complete one frame into ``stage``; returns its (H, W)."""
    from semattnet.viz.depth import colorize_depth
    from semattnet.viz.panels import branch_panel

    image, sem, lidar = _read_frame(frame)
    result = completer(image, lidar, sem)
    depth = clamp_for_png(result.depth, frame.name)
    write_depth(stage / f"{frame.name}.png", depth)
    write_image(stage / f"{frame.name}_color.png", colorize_depth(depth))
    if npy:
        with atomic_path(stage / f"{frame.name}.npy", suffix=".npy") as tmp:
            np.save(tmp, result.depth.astype(np.float32))
    if panel:
        branch_panel(stage / f"{frame.name}_panel.png", image, sem, lidar, result.outputs)
    return result.depth.shape[0], result.depth.shape[1]
