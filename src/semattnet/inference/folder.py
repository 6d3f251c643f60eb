"""Completing a user's frames from files to files: what ``semattnet predict --rgb/--sparse`` does, for Python
too. A thin wrapper of the one frame loop (:func:`semattnet.inference.pipeline.complete_frames`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from semattnet.data.pairing import FramePaths
from semattnet.data.sources.folder import FolderSource
from semattnet.inference import pipeline
from semattnet.inference.pipeline import Completer, OutputSpec, RunOptions
from semattnet.inference.sinks import OutputSettings, PanelOptions, default_sinks, output_files

__all__ = ["Completer", "check_frame_paths", "complete_folder", "output_paths"]


def output_paths(frames: Sequence[FramePaths], out: Path, npy: bool = False, panel: bool = False) -> list[Path]:
    """The files :func:`complete_folder` writes: ``NAME.png`` (16-bit depth) and ``NAME_color.png``,
    with ``NAME.npy`` / ``NAME_panel.png`` when asked."""
    return [
        Path(out) / p
        for p in output_files([f.name for f in frames], default_sinks(OutputSettings(npy=npy), PanelOptions(panel)))
    ]


def check_frame_paths(frames: Sequence[FramePaths]) -> None:
    """Decode every input of every frame (raising :class:`DataError` / ``UnknownColorError`` naming
    the file) before anything is written."""
    FolderSource(frames).check()


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
    on_error: str = "stop",
) -> list[Path]:
    """Complete ``frames`` (see :func:`semattnet.data.pairing.pair_frames`) and write, per frame,
    ``NAME.png`` (KITTI 16-bit depth), ``NAME_color.png`` and optionally ``NAME.npy`` (float32
    metres) and ``NAME_panel.png`` (per-branch panel) into ``out``.

    The output policy (:mod:`semattnet._utils.outputs`): ``out`` may not be (inside) an input folder;
    every input is decoded before any work; each frame's files appear atomically once it is done and are
    recorded in ``out/frames.json``. ``on_error``: ``"stop"`` (a corrupt frame raises, the frames done
    before it kept) or ``"skip"`` (it is skipped and noted in ``frames.json``); see
    :func:`~semattnet.inference.pipeline.complete_frames`.

    ``inputs``: the paths the user gave (files or folders; ``predict`` passes --rgb/--sparse/--semantic):
    ``out`` may not be one of these folders or inside one. ``out`` may never be the folder of an input
    file, and no output may resolve to an input file.

    Under ``torchrun`` (same arguments on every rank) the frames are split over the processes and
    the files are those of one process (:mod:`semattnet.inference.sharding`).

    Raises:
        FileExistsError: an output exists and ``overwrite`` is not set (checked before any work).
        OutputError: ``out`` is an input folder or inside one.
    """
    source = FolderSource(frames, given=inputs or ())
    plan = pipeline.check_frames(
        source,
        default_sinks(OutputSettings(npy=npy), PanelOptions(panel)),
        out,
        OutputSpec(overwrite),
        RunOptions(on_error),
    )
    return plan.run(completer, log=log).paths
