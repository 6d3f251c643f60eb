"""Completing frames of a KITTI raw drive straight from its images, scans and calibration
(what ``semattnet predict --kitti-raw`` runs): no intermediate sparse maps on disk. A thin wrapper of
the one frame loop (:func:`semattnet.inference.pipeline.complete_frames`) over a
:class:`~semattnet.data.sources.RawDriveSource` (which projects each scan).

Per frame ``NAME`` it writes ``NAME.png`` (KITTI 16-bit depth), ``NAME_color.png`` and optionally ``NAME.ply``
(the prediction back-projected into the camera frame: x right, y down, z forward, metres, with the image's
colours and, for SemAttNet, the largest of the three fusion weights as ``confidence``), ``NAME.npy`` and
``NAME_panel.png`` (the per-branch panel with a bird's-eye view of the cloud, the LiDAR scan overlaid).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

from semattnet.data.sources.raw_drive import RawDriveSource, project_frame
from semattnet.data.sources.semantic import MapSegmenter
from semattnet.inference.pipeline import Completer, OutputSpec, RunOptions, check_frames
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sinks import (
    OutputSettings,
    PanelOptions,
    PlyOptions,
    default_sinks,
    fusion_confidence,
    output_files,
)

__all__ = ["complete_kitti_raw", "fusion_confidence", "project_frame", "raw_output_paths"]


def raw_output_paths(
    names: Sequence[str], out: Path, ply: bool = False, npy: bool = False, panel: bool = False
) -> list[Path]:
    """Every file :func:`complete_kitti_raw` writes for ``names``."""
    return [
        Path(out) / p
        for p in output_files(names, default_sinks(OutputSettings(npy=npy), PlyOptions(ply), PanelOptions(panel)))
    ]


def complete_kitti_raw(
    completer: Completer,
    drive_dir: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    frames: str | int | Sequence[int] | None = None,
    camera: str | int = 2,
    semantic: str | os.PathLike[str] | None = None,
    segmenter: MapSegmenter | str | None = None,
    ply: bool = False,
    max_depth: float = 80.0,
    top_crop: int = 0,
    npy: bool = False,
    panel: bool = False,
    deskew: bool = False,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
    on_error: str = "stop",
) -> list[Path]:
    """Complete frames of a KITTI raw drive (see :class:`semattnet.data.kitti.raw.RawDrive`) into ``out``.

    Args:
        completer: a :class:`~semattnet.inference.DepthCompleter`, :class:`~semattnet.baselines.ClassicalCompleter` or
            anything with their call.
        drive_dir: ``RAW_ROOT/DATE/DATE_drive_NNNN_sync``. frames: ``"a-b"``, ``"1,3"``, indices or None (all).
        camera: 2 or 3. semantic: folder of colour-coded maps named like the images. segmenter: a
            :class:`~semattnet.segmentation.segmenter.Segmenter` or its SPEC. Without either, models that need semantics
            get the fallback map.
        ply: also write ``NAME.ply``; ``max_depth`` (metres) and ``top_crop`` (rows) select its pixels.
        deskew: ego-motion compensate the scans with their OXTS packets before projecting.

    Returns:
        The depth PNGs written.

    Raises:
        FileExistsError: an output exists and ``overwrite`` is not set (checked before any work).
        OutputError: ``out`` is the drive or semantic folder, or inside one.
        DataError: missing/corrupt drive files or frames, naming them.

    Each frame's files appear atomically once it is done, recorded in ``out/frames.json``; ``on_error``:
    ``"stop"`` (a corrupt frame raises, the frames done before it kept) or ``"skip"`` (noted and skipped;
    :func:`~semattnet.inference.pipeline.complete_frames`). Under ``torchrun``
    the frames are split over the processes, with the files of one process (:mod:`.sharding`).
    """
    maps = SemanticMaps(segmenter, folder=semantic is not None)
    source = RawDriveSource(drive_dir, frames, camera, semantic, deskew)
    settings = OutputSettings(npy=npy, max_depth=max_depth, top_crop=top_crop)
    sinks = default_sinks(settings, PlyOptions(ply), PanelOptions(panel))
    plan = check_frames(source, sinks, out, OutputSpec(overwrite), RunOptions(on_error))
    return plan.run(completer, semantic=maps, log=log).paths
