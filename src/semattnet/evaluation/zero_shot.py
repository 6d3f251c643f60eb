"""The zero-shot benchmark's pieces: the frames it scores, the methods it runs and the scores it keeps.

Frames: the bundled real KITTI frame (:func:`real_frames`: drive 0035, frame 5, cameras 02 and 03, its Velodyne
scan projected as ``predict --kitti-raw`` projects it, scored against the official annotated map) and held-out
scenes of the synthetic world (:func:`world_frames`: seeds of the ``heldout`` split, which training never
draws). Methods: ``benchmarks/zero_shot.py`` runs them (``classical``, the generalist's ``anchor``, weights).
Scores (:func:`score`): the KITTI metrics, REL,
the uncertainty's 2-sigma coverage (the share of pixels whose error is within twice the predicted standard
deviation) and its AUSE (RMSE sparsification, :mod:`semattnet.evaluation.sparsification`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from semattnet.evaluation.metrics import image_metrics
from semattnet.evaluation.sparsification import ause, oracle_curve, sparsification_curve

__all__ = ["BenchFrame", "DepthMethod", "real_frames", "score", "world_frames"]

#: The bundled real frame, relative to a KITTI sample root (``tests/data/kitti_sample``).
REAL_DRIVE = "kitti_raw/2011_09_26/2011_09_26_drive_0035_sync"
REAL_GT = "data_depth_annotated/train/2011_09_26_drive_0035_sync/proj_depth/groundtruth/image_0{camera}/0000000005.png"

#: The cloud gate the scores try: ``--max-uncertainty 10%`` (a standard deviation of at most 10 % of the depth).
GATE = 0.10

#: rgb (H, W, 3), sparse (H, W) metres -> (depth, uncertainty or None), (H, W) metres.
DepthMethod = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray | None]]


@dataclass
class BenchFrame:
    """One scored frame: inputs, the ground truth (metres, 0 = none) and where it comes from."""

    name: str
    rgb: np.ndarray
    sparse: np.ndarray
    gt: np.ndarray
    group: str  # "real", "street", "indoor"
    pattern: str


def real_frames(sample_root: str | Path) -> list[BenchFrame]:
    """The bundled real frame seen by cameras 02 and 03 (sparse: its own scan projected; truth: the annotation)."""
    return [_real_frame(Path(sample_root), "2"), _real_frame(Path(sample_root), "3")]


def _real_frame(root: Path, camera: str) -> BenchFrame:
    from semattnet.data.io import read_depth
    from semattnet.data.sources.raw_drive import RawDriveSource

    frame = RawDriveSource(root / REAL_DRIVE, "5", camera).load("0000000005")
    gt = read_depth(root / REAL_GT.format(camera=camera))
    return BenchFrame(f"kitti-0035-5-cam0{camera}", frame.rgb, frame.sparse, gt, "real", "lidar64")


def world_frames(
    kind: str, pattern: str, frames: int, size: tuple[int, int] | None = None, first: int = 0, **draw: object
) -> Iterator[BenchFrame]:
    """``frames`` held-out world frames of one ``kind`` and sparse ``pattern`` (``draw``: the pattern's own
    settings, e.g. ``beams=16`` or ``count=500``: :data:`~semattnet.synthetic.world.PATTERN_OPTIONS`)."""
    from semattnet.synthetic.world import make_world_frame, world_seed

    for i in range(first, first + frames):
        f = make_world_frame(world_seed("heldout", i), kind=kind, pattern=pattern, size=size, **draw)
        label = pattern + "".join(f"-{k}{v}" for k, v in draw.items())
        yield BenchFrame(f"{kind}-{label}-{i}", f.rgb, f.sparse, f.gt, kind, label)


def score(depth: np.ndarray, gt: np.ndarray, uncertainty: np.ndarray | None = None) -> dict[str, float]:
    """RMSE and MAE (mm), iRMSE and iMAE (1/km), REL over the pixels with truth (KITTI's hole filling as the devkit
    does it), and with an uncertainty its 2-sigma coverage (%), AUSE (RMSE sparsification, normalised curves) and what
    the cloud gate ``--max-uncertainty 10%`` keeps (% of the pixels, their RMSE) over the pixels with truth and a
    depth."""
    pred_t, gt_t = torch.from_numpy(np.asarray(depth, np.float32))[None, None], torch.from_numpy(gt)[None, None]
    m = image_metrics(pred_t, gt_t.float())
    out = {
        "rmse_mm": 1000 * float(m["rmse"][0]),
        "mae_mm": 1000 * float(m["mae"][0]),
        "irmse_per_km": 1000 * float(m["irmse"][0]),
        "imae_per_km": 1000 * float(m["imae"][0]),
        "rel": float(m["abs_rel"][0]),
    }
    if uncertainty is not None:  # over the pixels with truth and a depth (one left without has no uncertainty)
        valid = (gt > 0) & (np.asarray(depth) > 0)
        err = (depth - gt)[valid].astype(np.float64)
        sigma = np.asarray(uncertainty, np.float64)[valid]
        out["coverage_2sigma_pct"] = 100.0 * float(np.mean(np.abs(err) <= 2 * sigma))
        out["ause_rmse"] = ause(sparsification_curve(err, sigma), oracle_curve(err))
        kept = sigma <= GATE * depth[valid]  # what `--max-uncertainty 10%` keeps in a cloud
        out["gate_kept_pct"] = 100.0 * float(np.mean(kept))
        out["gate_rmse_mm"] = 1000.0 * float(np.sqrt(np.mean(err[kept] ** 2))) if kept.any() else math.nan
    return out


def mean_scores(rows: list[dict[str, float]]) -> dict[str, float]:
    """The per-key mean of several frames' :func:`score` (keys every row has)."""
    keys = set.intersection(*(set(r) for r in rows)) if rows else set()
    return {k: float(np.mean([r[k] for r in rows])) for k in sorted(keys) if not any(math.isnan(r[k]) for r in rows)}
