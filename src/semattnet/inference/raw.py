"""Completing frames of a KITTI raw drive straight from its images, scans and calibration
(what ``semattnet predict --kitti-raw`` runs): no intermediate sparse maps on disk.

Per frame ``NAME`` it writes ``NAME.png`` (KITTI 16-bit depth), ``NAME_color.png`` and optionally ``NAME.ply``
(the prediction back-projected into the camera frame: x right, y down, z forward, metres, with the image's
colours and, for SemAttNet, the largest of the three fusion weights as ``confidence``), ``NAME.npy`` and
``NAME_panel.png`` (the per-branch panel with a bird's-eye view of the cloud, the LiDAR scan overlaid).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from semattnet._utils.atomic import atomic_path
from semattnet._utils.outputs import check_no_input_overlap, refuse_existing
from semattnet.data.io import DataError, clamp_for_png, encode_depth, read_semantic, write_depth, write_image
from semattnet.data.kitti_raw import RawDrive, RawFrame
from semattnet.inference.folder import Completer
from semattnet.inference.sharding import agree, on_main, process_group, rank_log, shard, shared_stage

__all__ = ["complete_kitti_raw", "fusion_confidence", "project_frame", "raw_output_paths"]

#: The per-pixel fusion weights of SemAttNet (see :class:`semattnet.models.outputs.DepthCompletionOutput`).
CONFIDENCE_KEYS = ("color_conf", "semantic_conf", "guided_conf")


def fusion_confidence(outputs: dict[str, np.ndarray]) -> np.ndarray | None:
    """(H, W) largest fusion weight across the branches, or None when the method has none (classical)."""
    confs = [np.asarray(outputs[k], dtype=np.float32) for k in CONFIDENCE_KEYS if k in outputs]
    return np.max(np.stack(confs), axis=0) if confs else None


def raw_output_paths(names: Sequence[str], out: Path, ply: bool = False, npy: bool = False,
                     panel: bool = False) -> list[Path]:  # fmt: skip
    """Every file :func:`complete_kitti_raw` writes for ``names``."""
    suffixes = [".png", "_color.png"] + [".ply"] * ply + [".npy"] * npy + ["_panel.png"] * panel
    return [Path(out) / f"{name}{suffix}" for name in names for suffix in suffixes]


def _semantic_source(
    completer: Completer, semantic: str | os.PathLike[str] | None, segmenter: Any
) -> Callable[[RawFrame], np.ndarray | None]:
    """How each frame gets its semantic map: a folder of same-named PNGs, a segmenter, or the fallback."""
    from semattnet.data.palette import ids_to_colors, unknown_map

    if semantic is not None and segmenter is not None:
        raise ValueError("give a semantic folder or a segmenter, not both")
    if semantic is not None:
        folder = Path(semantic)
        if not folder.is_dir():
            raise DataError(f"{folder}: semantic folder not found")
        return lambda frame: read_semantic(folder / f"{frame.name}.png")
    if segmenter is not None:
        if isinstance(segmenter, str):
            from semattnet.segmentation.segmenter import load_segmenter

            segmenter = load_segmenter(segmenter, getattr(completer, "device", "auto"))
        return lambda frame: ids_to_colors(segmenter(frame.image[None])[0])
    if getattr(completer, "needs_semantic", False):
        warnings.warn("no semantic maps given (--semantic or --segment): using the 'unknown' fallback map, "
                      "which costs accuracy", stacklevel=4)  # fmt: skip
        return lambda frame: unknown_map(*frame.image.shape[:2])
    return lambda frame: None


def _bird_eye_tile(cloud: Any, frame: RawFrame, shape: tuple[int, int], max_depth: float) -> np.ndarray:
    """A square bird's-eye view (ahead up to min(max_depth, 50) m) centred in an (H, W) tile, with the LiDAR
    points that fall inside the image overlaid."""
    from semattnet.geometry import points_to_pixels, transform_points
    from semattnet.viz.pointcloud import birds_eye_view

    calib = frame.calib
    uv, z = points_to_pixels(frame.points, calib.K, calib.T_cam_lidar)
    w, h = calib.image_size
    seen = (z > 0.1) & (uv[:, 0] >= -0.5) & (uv[:, 0] < w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < h - 0.5)
    lidar = transform_points(calib.T_cam_lidar, np.asarray(frame.points[seen, :3], dtype=np.float64))
    far = float(min(max_depth, 50.0))
    side = min(shape)
    bev = birds_eye_view(cloud, size=(side, side), x_range=(-far / 2, far / 2), z_range=(0.0, far), lidar=lidar)
    tile = np.zeros((*shape, 3), dtype=np.uint8)
    top, left = (shape[0] - side) // 2, (shape[1] - side) // 2
    tile[top : top + side, left : left + side] = bev
    return tile


def _write_frame(frame: RawFrame, sparse: np.ndarray, sem: np.ndarray | None, result: Any, out: Path,
                 opts: dict[str, Any]) -> Path:  # fmt: skip
    """Write one frame's outputs; the PLY and the panel use the depth exactly as stored in the PNG."""
    from semattnet.geometry import depth_to_points, write_ply
    from semattnet.viz.depth import colorize_depth
    from semattnet.viz.panels import branch_panel

    depth = np.asarray(result.depth, dtype=np.float32).copy()
    valid = depth > 0  # 0 = no prediction (e.g. the classical method above the LiDAR's reach) stays 0
    depth[valid] = clamp_for_png(depth[valid], frame.name)
    path = write_depth(out / f"{frame.name}.png", depth, overwrite=True)
    write_image(out / f"{frame.name}_color.png", colorize_depth(depth), overwrite=True)
    if opts["npy"]:
        with atomic_path(out / f"{frame.name}.npy", suffix=".npy") as tmp:
            np.save(tmp, result.depth.astype(np.float32))
    cloud = None
    if opts["ply"] or opts["panel"]:
        stored = encode_depth(depth).astype(np.float32) / 256.0
        cloud = depth_to_points(stored, frame.calib.K, rgb=frame.image, confidence=fusion_confidence(result.outputs),
                                max_depth=opts["max_depth"], top_crop=opts["top_crop"],
                                frame=f"cam{frame.calib.camera}")  # fmt: skip
    if opts["ply"]:
        write_ply(out / f"{frame.name}.ply", cloud, overwrite=True)
    if opts["panel"]:
        bev = _bird_eye_tile(cloud, frame, depth.shape, opts["max_depth"])
        branch_panel(out / f"{frame.name}_panel.png", frame.image, sem, sparse, result.outputs,
                     extra=[("bird's-eye view (LiDAR in magenta)", bev)])  # fmt: skip
    return path


def complete_kitti_raw(
    completer: Completer,
    drive_dir: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    frames: str | int | Sequence[int] | None = None,
    camera: str | int = 2,
    semantic: str | os.PathLike[str] | None = None,
    segmenter: Any = None,
    ply: bool = False,
    max_depth: float = 80.0,
    top_crop: int = 0,
    npy: bool = False,
    panel: bool = False,
    deskew: bool = False,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Complete frames of a KITTI raw drive (see :class:`semattnet.data.kitti_raw.RawDrive`) into ``out``.

    Args:
        completer: a :class:`DepthCompleter`, :class:`ClassicalCompleter` or anything with their call.
        drive_dir: ``RAW_ROOT/DATE/DATE_drive_NNNN_sync``. frames: ``"a-b"``, ``"1,3"``, indices or None (all).
        camera: 2 or 3. semantic: folder of colour-coded maps named like the images. segmenter: a
            :class:`Segmenter` or its SPEC. Without either, models that need semantics get the fallback map.
        ply: also write ``NAME.ply``; ``max_depth`` (metres) and ``top_crop`` (rows) select its pixels.
        deskew: ego-motion compensate the scans with their OXTS packets before projecting.

    Returns:
        The depth PNGs written.

    Raises:
        FileExistsError: an output exists and ``overwrite`` is not set (checked before any work).
        OutputError: ``out`` is the drive or semantic folder, or inside one.
        DataError: missing/corrupt drive files or frames, naming them.

    Outputs are staged (:func:`semattnet._utils.outputs.staged_outputs`): they appear in ``out`` only
    when every frame succeeded; a corrupt frame or a kill leaves ``out`` unchanged. Under ``torchrun``
    the frames are split over the processes, with the files of one process (:mod:`.sharding`).
    """
    out = Path(out)
    with process_group():
        drive, names = agree(_open_drive, drive_dir, out, semantic, camera, deskew, frames)
        expected = raw_output_paths(names, out, ply, npy, panel)
        on_main(refuse_existing, expected, overwrite)
        semantic_for = agree(_semantic_source, completer, semantic, segmenter)
        opts = {"ply": ply, "npy": npy, "panel": panel, "max_depth": max_depth, "top_crop": top_crop}
        log = rank_log(log)
        with shared_stage(out, overwrite, [p.relative_to(out) for p in expected]) as stage:
            for name in shard(names):
                frame = drive.frame(name)
                sparse = project_frame(frame)
                sem = semantic_for(frame)
                result = completer(frame.image, sparse, sem)
                _write_frame(frame, sparse, sem, result, stage, opts)
                log(f"{name}: {np.count_nonzero(sparse)} LiDAR pixels, {sparse.shape[1]}x{sparse.shape[0]} "
                    f"-> {out / (name + '.png')}")  # fmt: skip
    return [out / f"{name}.png" for name in names]


def _open_drive(drive_dir: str | os.PathLike[str], out: Path, semantic: str | os.PathLike[str] | None,
                camera: str | int, deskew: bool,
                frames: str | int | Sequence[int] | None) -> tuple[RawDrive, list[str]]:  # fmt: skip
    """The drive and the names of the frames to complete, after checking ``out`` is outside the inputs."""
    check_no_input_overlap([drive_dir, semantic], out_dir=out)
    drive = RawDrive(drive_dir, camera, deskew=deskew)
    return drive, list(drive.names_for(frames))


def project_frame(frame: RawFrame) -> np.ndarray:
    """(H, W) float32 sparse depth of a raw frame's scan in its camera (metres, 0 = none)."""
    from semattnet.geometry import project_points

    return project_points(frame.points, frame.calib.K, frame.calib.T_cam_lidar, frame.calib.image_size,
                          name=str(frame.scan_path))  # fmt: skip
