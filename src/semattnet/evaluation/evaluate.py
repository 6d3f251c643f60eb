"""Scoring: a model over a data loader, a checkpoint over a KITTI split, prediction folders against ground truth.

Every score goes through :class:`~semattnet.evaluation.metrics.KittiMetrics` (the devkit's rule).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import DataLoader, Subset
from tqdm import tqdm

from semattnet._utils import distributed as dist_utils
from semattnet._utils.device import autocast
from semattnet._utils.outputs import check_no_input_overlap, write_text
from semattnet.data.io import DEPTH_SCALE, DataError, clamp_for_png, read_depth, write_depth
from semattnet.data.kitti import KittiDepthCompletion
from semattnet.data.transforms import EvalTransform
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.inference.completer import DepthCompleter
from semattnet.inference.sharding import agree, gather_rows, on_main, process_group, shared_stage

__all__ = ["evaluate_checkpoint", "evaluate_model", "score_folders", "score_folders_to_json"]


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


def evaluate_model(
    model: nn.Module,
    loader: DataLoader,
    device: torch.device,
    amp: str = "none",
    progress: bool = True,
    on_batch: Callable[[dict[str, Any], Any], None] | None = None,
    fill_holes: bool = True,
    min_gt: float = 0.0,
    quantize: bool = False,
) -> KittiMetrics:
    """Score ``model`` over ``loader`` (batches from :class:`KittiDepthCompletion`), all ranks.

    ``quantize`` scores what a KITTI 16-bit PNG of the prediction holds (clamped, 1/256 m steps,
    holes kept as 0 for the devkit to fill), i.e. exactly what ``semattnet metrics`` and the benchmark see.
    """
    metrics = _score_local(model, loader, device, amp, progress, on_batch, fill_holes, min_gt, quantize)
    metrics.reduce()
    return metrics


def _score_local(model: nn.Module, loader: DataLoader, device: torch.device, amp: str, progress: bool,
                 on_batch: Callable[[dict[str, Any], Any], None] | None, fill_holes: bool, min_gt: float,
                 quantize: bool) -> KittiMetrics:  # fmt: skip
    """:func:`evaluate_model` on this rank's batches only (no collective)."""
    metrics = KittiMetrics(fill_holes=fill_holes, min_gt=min_gt)
    was_training = model.training
    model.eval()
    with torch.inference_mode():
        for batch in tqdm(loader, desc="evaluating", disable=not (progress and dist_utils.is_main()), leave=False):
            x = {k: batch[k].to(device, non_blocking=True) for k in ("rgb", "semantic", "sparse")}
            with autocast(device, amp):
                out = model(**x)
            if "gt" in batch:
                pred = out.depth.float()
                if quantize:
                    pred = _as_png(pred, list(batch["name"]))
                metrics.update(pred, batch["gt"].to(device), names=list(batch["name"]))
            if on_batch is not None:
                on_batch(batch, out)
    model.train(was_training)
    return metrics


def _as_png(pred: torch.Tensor, names: list[str]) -> torch.Tensor:
    """What the 16-bit PNGs of (B, 1, H, W) predictions hold: :func:`clamp_for_png`, 1/256 m steps."""
    clamped = torch.stack([clamp_for_png(p, name) for p, name in zip(pred, names, strict=True)])
    return torch.round(clamped * DEPTH_SCALE) / DEPTH_SCALE


def _prediction_name(split: str, frame_name: str, gt_path: Path | None) -> str:
    # val_select: the ground truth's own file name, so `semattnet metrics` pairs by name.
    return gt_path.name if split == "val_select" and gt_path is not None else f"{frame_name}.png"


def _eval_dataset(data: str | Path, split: str, raw_root: str | Path | None,
                  semantic_root: str | Path | None) -> KittiDepthCompletion:  # fmt: skip
    """The split as the benchmark scores it: val_select at full size, val cropped to 352x1216
    (small synthetic trees: full frames)."""
    ds = KittiDepthCompletion(data, split, raw_root, semantic_root,
                              transform=EvalTransform(None if split == "val_select" else (352, 1216)))  # fmt: skip
    if split == "val" and min(ds.load(0).size) < 352:
        ds.transform = EvalTransform(None)
    return ds


def score_folders_to_json(pred_dir: str | Path, gt_dir: str | Path, json_path: str | Path | None = None,
                          overwrite: bool = False, fill_holes: bool = True,
                          min_gt: float = 0.0) -> KittiMetrics:  # fmt: skip
    """:func:`score_folders`, then (optionally) the metrics as JSON in ``json_path``: never an input
    file, never replacing an existing file unless ``overwrite`` (both checked before scoring)."""
    if json_path is not None:
        check_no_input_overlap([pred_dir, gt_dir], out_files=[json_path])
        if Path(json_path).exists() and not overwrite:
            raise FileExistsError(f"{json_path} exists; pass --overwrite to replace it")
    metrics = score_folders(pred_dir, gt_dir, fill_holes=fill_holes, min_gt=min_gt)
    if json_path is not None:
        write_text(json_path, json.dumps(metrics.compute(), indent=2) + "\n", overwrite=overwrite)
    return metrics


def _prepare_out(out: Path, overwrite: bool, inputs: Sequence[Any] = ()) -> Path:
    """Check ``out``: not inside an input; a non-empty folder needs ``overwrite`` (which replaces
    only the files the evaluation writes)."""
    check_no_input_overlap(inputs, out_dir=out)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"{out} is not empty; pass --overwrite to replace its contents")
    out.mkdir(parents=True, exist_ok=True)
    return out


class _FrameWriter:
    """``on_batch`` callback of :func:`evaluate_model`: writes 16-bit predictions and the branch
    panels of the first ``pictures`` frames."""

    def __init__(self, ds: KittiDepthCompletion, split: str, out: Path, save_predictions: bool, pictures: int) -> None:
        self.ds, self.split, self.out = ds, split, out
        self.save_predictions, self.pictures = save_predictions, pictures

    def expected(self, frames: int) -> list[str]:
        """The files written for the first ``frames`` frames, relative to ``out``."""
        todo = self.ds.frames[:frames]
        preds = [f"predictions/{_prediction_name(self.split, f.name, f.gt)}" for f in todo]
        return preds * self.save_predictions + [f"pictures/{f.name}.png" for f in todo[: self.pictures]]

    def __call__(self, batch: dict[str, Any], result: Any) -> None:
        for i, idx in enumerate(batch["index"].tolist()):
            frame = self.ds.frames[idx]
            if self.save_predictions:
                depth = clamp_for_png(result.depth[i, 0].float().cpu().numpy(), frame.name)
                name = _prediction_name(self.split, frame.name, frame.gt)
                write_depth(self.out / "predictions" / name, depth, overwrite=True)
            if idx < self.pictures:  # the split's first frames, whichever rank scores them
                self._panel(batch, result, i, frame.name)

    def _panel(self, batch: dict[str, Any], result: Any, i: int, name: str) -> None:
        from semattnet.viz.panels import branch_panel

        outputs = {k: v[i, 0].float().cpu().numpy() for k, v in result.to_dict().items()}
        gt = batch["gt"][i, 0].numpy() if "gt" in batch else None
        rgb, sem = (batch[k][i].permute(1, 2, 0).numpy() for k in ("rgb", "semantic"))
        branch_panel(self.out / "pictures" / f"{name}.png", rgb, sem, batch["sparse"][i, 0].numpy(), outputs, gt)


def _write_scores(out: Path, metrics: KittiMetrics, summary: dict[str, Any]) -> None:
    """``metrics.json`` (the summary) and ``per_image.csv`` (one row per frame)."""
    (out / "metrics.json").write_text(json.dumps(summary, indent=2) + "\n")
    with open(out / "per_image.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(metrics.per_image[0]))
        writer.writeheader()
        writer.writerows(metrics.per_image)


def evaluate_checkpoint(
    checkpoint: str | Path | nn.Module,
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
    backend: str = "torch",
) -> dict[str, Any]:
    """Run a checkpoint (a path, or a loaded model) over a split and score it; optionally write
    predictions and panels. ``backend`` chooses the inference engine
    (:func:`semattnet.inference.backends.optimize_for_inference`; fixed-size backends are built for
    the split's frame size).

    Writes into ``out_dir``: ``metrics.json``, ``per_image.csv``, ``predictions/`` (16-bit PNGs named
    like the ground truth for val_select) and ``pictures/`` (branch panels of the first frames).

    Under ``torchrun`` (same arguments on every rank; ``cuda:LOCAL_RANK`` on GPUs) rank ``r`` of ``W``
    scores frames ``r, r + W, ...`` (each frame once); the metrics are summed over the ranks and the
    per-image rows gathered in the split's order, so the files are those of one process.
    """
    completer, label = _completer(checkpoint, device, amp, backend)
    inputs = [data, raw_root, semantic_root, None if isinstance(checkpoint, nn.Module) else checkpoint]
    with process_group():
        out = on_main(_prepare_out, Path(out_dir), overwrite, inputs) if out_dir is not None else None
        ds = _eval_dataset(data, split, raw_root, semantic_root)
        frames = min(len(ds), max_frames) if max_frames else len(ds)
        loader = DataLoader(Subset(ds, range(frames)), batch_size=batch_size, num_workers=workers,
                            sampler=dist_utils.ShardSampler(frames))  # fmt: skip
        engine = completer.engine(tuple(ds[0]["rgb"].shape[-2:])) if frames else completer.model
        score = partial(_score_local, engine, loader, completer.device, amp, True,
                        fill_holes=True, min_gt=0.0, quantize=True)  # fmt: skip
        if out is None:
            metrics = _merge(agree(score, None), ds)
            return {"metrics": metrics, "result": metrics.compute() if metrics.per_image else {}}
        writer = _FrameWriter(ds, split, out, save_predictions, pictures)
        expected = writer.expected(frames)
        with shared_stage(out, overwrite, expected) as stage:  # all files appear together, or none
            writer.out = stage
            metrics = _merge(agree(score, writer), ds)
            result = metrics.compute() if metrics.per_image else {}
            if result:
                expected += ["metrics.json", "per_image.csv"]
                if dist_utils.is_main():
                    _write_scores(stage, metrics, {"checkpoint": label, "split": split} | result)
    return {"metrics": metrics, "result": result}


def _completer(checkpoint: str | Path | nn.Module, device: str, amp: str, backend: str) -> tuple[DepthCompleter, str]:
    """The completer (on ``cuda:LOCAL_RANK`` under torchrun with CUDA) and how metrics.json names it."""
    device_ = dist_utils.process_device(device)
    if isinstance(checkpoint, nn.Module):
        return DepthCompleter(checkpoint, device=device_, amp=amp, backend=backend), type(checkpoint).__name__
    return DepthCompleter.from_checkpoint(checkpoint, device=device_, amp=amp, backend=backend), str(checkpoint)


def _merge(metrics: KittiMetrics, ds: KittiDepthCompletion) -> KittiMetrics:
    """``metrics`` summed over the ranks, with every rank's per-image rows in the split's order (collective)."""
    metrics.reduce()
    position = {frame.name: i for i, frame in enumerate(ds.frames)}
    metrics.per_image = gather_rows(metrics.per_image, key=lambda row: position[str(row["name"])])
    return metrics
