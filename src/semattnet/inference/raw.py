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
from dataclasses import dataclass
from pathlib import Path

from semattnet._errors import InputError
from semattnet.data.kitti.raw import parse_frames
from semattnet.data.sources.raw_drive import RawDriveSource, project_frame
from semattnet.data.sources.semantic import MapSegmenter
from semattnet.inference.pipeline import Completer, OutputSpec, RunOptions, check_frames
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sinks import (
    OutputSettings,
    PanelOptions,
    PlyOptions,
    SinkOptions,
    default_sinks,
    fusion_confidence,
    output_files,
)

__all__ = ["RawDriveSelection", "complete_kitti_raw", "fusion_confidence", "project_frame", "raw_output_paths"]

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class RawDriveSelection:
    """Which frames of a KITTI raw drive :func:`complete_kitti_raw` reads, and how.

    ``frames``: ``"a-b"``, ``"1,3"``, an index, indices or None (all). ``camera``: 0 to 3 (KITTI's colour cameras
    are 2 and 3). ``semantic``: a folder of colour-coded maps named like the images; ``segmenter``: a
    :class:`~semattnet.segmentation.segmenter.Segmenter` or its SPEC (one or the other; without either, models
    that need semantics get the fallback map). ``deskew``: ego-motion compensate the scans with their OXTS packets.

    Raises:
        InputError: a bad value, in one line naming the field.
    """

    frames: str | int | Sequence[int] | None = None
    camera: str | int = 2
    semantic: PathLike | None = None
    segmenter: MapSegmenter | str | None = None
    deskew: bool = False

    def __post_init__(self) -> None:
        try:
            parse_frames(self.frames)
        except (TypeError, ValueError) as e:  # a DataError (a ValueError) names the spec already
            raise InputError(f"frames: not frame indices: {self.frames!r} ({e})") from None
        if isinstance(self.camera, bool) or not (str(self.camera).isdigit() and int(self.camera) <= 3):
            raise InputError(f"camera: must be 0 to 3 (KITTI's colour cameras: 2, 3), got {self.camera!r}")
        if not isinstance(self.deskew, bool):
            raise InputError(f"deskew: must be True or False, got {self.deskew!r}")
        if self.semantic is not None and self.segmenter is not None:
            raise InputError(f"semantic: give a semantic folder or a segmenter, not both (got {self.semantic!r})")


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
    drive_dir: PathLike,
    out: PathLike,
    *,
    selection: RawDriveSelection | None = None,
    settings: OutputSettings | None = None,
    outputs: Sequence[SinkOptions] = (),
    output: OutputSpec | None = None,
    options: RunOptions | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Complete frames of a KITTI raw drive (see :class:`semattnet.data.kitti.raw.RawDrive`) into ``out``.

    Args:
        completer: a :class:`~semattnet.inference.DepthCompleter`, :class:`~semattnet.baselines.ClassicalCompleter` or
            anything with their call.
        drive_dir: ``RAW_ROOT/DATE/DATE_drive_NNNN_sync``.
        selection: the frames, camera, semantic maps and deskewing (:class:`RawDriveSelection`; default: every
            frame of camera 2).
        settings: what the outputs share (:class:`~semattnet.inference.sinks.OutputSettings`: ``npy``, and the
            ``max_depth`` (metres) and ``top_crop`` (rows) that select the clouds' pixels).
        outputs: the further files, as :func:`~semattnet.inference.sinks.default_sinks` takes them:
            ``PlyOptions(ply=True)`` (``NAME.ply``), ``PanelOptions(panel=True)`` (``NAME_panel.png``).
        output: the folder's rules (:class:`~semattnet.inference.options.OutputSpec`; ``overwrite``).
        options: how the frames are run (:class:`~semattnet.inference.options.RunOptions`; default
            ``on_error="stop"``).
        log: where the per-frame lines go.

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
    sel = selection or RawDriveSelection()
    maps = SemanticMaps(sel.segmenter, folder=sel.semantic is not None)
    source = RawDriveSource(drive_dir, sel.frames, sel.camera, sel.semantic, sel.deskew)
    sinks = default_sinks(settings, *outputs)
    plan = check_frames(source, sinks, out, output, options or RunOptions(on_error="stop"))
    return plan.run(completer, semantic=maps, log=log).paths
