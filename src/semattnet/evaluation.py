"""Scoring prediction folders, evaluating checkpoints on a split, and KITTI test submissions."""

from __future__ import annotations

import csv
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, Subset
from tqdm import tqdm

from ._atomic import atomic_path
from .data.io import DataError, read_depth, write_depth
from .data.kitti import KittiDepthCompletion
from .data.transforms import EvalTransform
from .engine import evaluate_model
from .inference import DepthCompleter, clamp_for_png
from .metrics import KittiMetrics

__all__ = ["SubmissionError", "evaluate_checkpoint", "score_folders", "write_submission", "write_submission_files"]

KITTI_TEST_FRAMES = 1000


class SubmissionError(ValueError):
    """A submission that would be rejected: wrong count, size or encoding."""


def score_folders(pred_dir: str | Path, gt_dir: str | Path, fill_holes: bool = True, min_gt: float = 0.0,
                  progress: bool = True) -> KittiMetrics:  # fmt: skip
    """Score 16-bit PNG predictions against ground truth, pairing files by name.

    Raises:
        DataError: the folders hold different file names (listed), or a pair differs in size.
    """
    pred_dir, gt_dir = Path(pred_dir), Path(gt_dir)
    preds = {p.name: p for p in pred_dir.glob("*.png")}
    gts = {p.name: p for p in gt_dir.glob("*.png")}
    if not gts:
        raise DataError(f"{gt_dir}: no PNG files")
    if preds.keys() != gts.keys():
        only_p, only_g = sorted(preds.keys() - gts.keys()), sorted(gts.keys() - preds.keys())
        raise DataError(f"{pred_dir} has {len(preds)} files, {gt_dir} {len(gts)}; "
                        f"without ground truth: {only_p[:5]}{' ...' if len(only_p) > 5 else ''}; "
                        f"without prediction: {only_g[:5]}{' ...' if len(only_g) > 5 else ''}")  # fmt: skip
    metrics = KittiMetrics(fill_holes=fill_holes, min_gt=min_gt)
    bad = []
    for name in tqdm(sorted(gts), desc="scoring", disable=not progress, leave=False):
        pred, gt = read_depth(preds[name]), read_depth(gts[name])
        if pred.shape != gt.shape:
            bad.append(
                f"{name}: prediction {pred.shape[1]}x{pred.shape[0]} vs ground truth {gt.shape[1]}x{gt.shape[0]}"
            )
            continue
        metrics.update(torch.from_numpy(pred)[None, None], torch.from_numpy(gt)[None, None], names=[name])
    if bad:
        raise DataError(f"size mismatch in {len(bad)} pair(s): " + "; ".join(bad[:5]))
    return metrics


def _prediction_name(split: str, frame_name: str, gt_path: Path | None) -> str:
    # val_select: the ground truth's own file name, so `semattnet metrics` pairs by name.
    return gt_path.name if split == "val_select" and gt_path is not None else f"{frame_name}.png"


def evaluate_checkpoint(
    checkpoint: str | Path,
    data: str | Path,
    split: str = "val_select",
    out_dir: str | Path | None = None,
    device: str = "auto",
    batch_size: int = 1,
    amp: str = "none",
    workers: int = 2,
    save_predictions: bool = False,
    pictures: int = 0,
    max_frames: int | None = None,
    overwrite: bool = False,
    raw_root: str | Path | None = None,
    semantic_root: str | Path | None = None,
) -> dict[str, Any]:
    """Run a checkpoint over a split and score it; optionally write predictions and panels.

    Writes into ``out_dir``: ``metrics.json``, ``per_image.csv``, ``predictions/`` (16-bit PNGs named
    like the ground truth for val_select) and ``pictures/`` (branch panels of the first frames).
    """
    completer = DepthCompleter.from_checkpoint(checkpoint, device=device, amp=amp)
    ds = KittiDepthCompletion(data, split, raw_root, semantic_root,
                              transform=EvalTransform(None if split == "val_select" else (352, 1216)))  # fmt: skip
    if split == "val" and min(ds.load(0).size) < 352:
        ds.transform = EvalTransform(None)  # small synthetic trees: full frames
    subset = Subset(ds, range(min(len(ds), max_frames))) if max_frames else ds
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        if out.exists() and any(out.iterdir()) and not overwrite:
            raise FileExistsError(f"{out} is not empty; pass --overwrite to replace its contents")
        out.mkdir(parents=True, exist_ok=True)
    shown = [0]

    def on_batch(batch: dict[str, Any], result: Any) -> None:
        if out is None:
            return
        for i, idx in enumerate(batch["index"].tolist()):
            frame = ds.frames[idx]
            if save_predictions:
                depth = clamp_for_png(result.depth[i, 0].float().cpu().numpy(), frame.name)
                write_depth(out / "predictions" / _prediction_name(split, frame.name, frame.gt), depth, overwrite=True)
            if shown[0] < pictures:
                from .visualize import branch_panel

                outputs = {k: v[i, 0].float().cpu().numpy() for k, v in result.to_dict().items()}
                gt = batch["gt"][i, 0].numpy() if "gt" in batch else None
                rgb, sem = (batch[k][i].permute(1, 2, 0).numpy() for k in ("rgb", "semantic"))
                branch_panel(
                    out / "pictures" / f"{frame.name}.png", rgb, sem, batch["sparse"][i, 0].numpy(), outputs, gt
                )
                shown[0] += 1

    loader = DataLoader(subset, batch_size=batch_size, num_workers=workers)
    metrics = evaluate_model(completer.model, loader, completer.device, amp, on_batch=on_batch, quantize=True)
    result = metrics.compute() if metrics.per_image else {}
    if out is not None and result:
        (out / "metrics.json").write_text(json.dumps({"checkpoint": str(checkpoint), "split": split} | result,
                                                     indent=2) + "\n")  # fmt: skip
        with open(out / "per_image.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(metrics.per_image[0]))
            writer.writeheader()
            writer.writerows(metrics.per_image)
    return {"metrics": metrics, "result": result}


def write_submission_files(
    predictions: Iterable[tuple[str, np.ndarray]],
    out: str | Path,
    expected: dict[str, tuple[int, int]],
    overwrite: bool = False,
) -> Path:
    """Write ``(file name, depth)`` pairs as KITTI 16-bit PNGs into ``out`` and zip them.

    Everything goes to a temporary folder first; ``out`` and the zip appear only when the count,
    every name, every size (``expected``: name -> (H, W)) and the encoding check out.

    Raises:
        SubmissionError: any check fails (nothing is written).
        FileExistsError: ``out`` exists and ``overwrite`` is not set.
    """
    out = Path(out)
    zip_path = out.with_suffix(".zip")
    if (out.exists() or zip_path.exists()) and not overwrite:
        raise FileExistsError(f"{out} or {zip_path} exists; pass --overwrite to replace them")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        for name, depth in predictions:
            if name not in expected:
                raise SubmissionError(f"unexpected prediction {name!r} (not a test frame)")
            if depth.shape != expected[name]:
                raise SubmissionError(f"{name}: prediction is {depth.shape[1]}x{depth.shape[0]}, "
                                      f"the input is {expected[name][1]}x{expected[name][0]}")  # fmt: skip
            write_depth(tmp / name, clamp_for_png(depth, name))
        written = sorted(p.name for p in tmp.glob("*.png"))
        if written != sorted(expected):
            missing = sorted(set(expected) - set(written))
            raise SubmissionError(f"{len(written)} predictions for {len(expected)} test frames; missing {missing[:5]}")
        for name in written:  # read back: 16-bit, right size, no zeros (0 = "no prediction")
            d = read_depth(tmp / name)
            if d.shape != expected[name] or not (d > 0).all():
                raise SubmissionError(f"{name}: failed the read-back check")
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    with atomic_path(zip_path) as tmp_zip, zipfile.ZipFile(tmp_zip, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(out.glob("*.png")):
            zf.write(p, arcname=p.name)
    return zip_path


def write_submission(
    checkpoint: str | Path,
    data: str | Path,
    out: str | Path,
    device: str = "auto",
    amp: str = "none",
    expected_frames: int | None = KITTI_TEST_FRAMES,
    overwrite: bool = False,
    semantic_root: str | Path | None = None,
) -> Path:
    """Predict the test split (``test_depth_completion_anonymous``) and write a ready-to-upload zip.

    ``expected_frames`` is KITTI's 1000; pass ``None`` to accept any count (e.g. synthetic data).
    """
    ds = KittiDepthCompletion(data, "test", semantic_root=semantic_root)
    if expected_frames is not None and len(ds) != expected_frames:
        raise SubmissionError(f"{data}: the test split has {len(ds)} frames, KITTI expects {expected_frames}")
    completer = DepthCompleter.from_checkpoint(checkpoint, device=device, amp=amp)
    expected = {f.sparse.name: read_depth(f.sparse).shape for f in ds.frames}

    def predictions() -> Iterable[tuple[str, np.ndarray]]:
        for i in tqdm(range(len(ds)), desc="test split", leave=False):
            x = ds[i]
            res = completer.run(x["rgb"][None], x["semantic"][None], x["sparse"][None])
            yield ds.frames[i].sparse.name, res.depth[0, 0].cpu().numpy()

    return write_submission_files(predictions(), out, expected, overwrite)
