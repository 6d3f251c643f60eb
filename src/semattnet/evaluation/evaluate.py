"""Scoring: a model over a data loader, a checkpoint over a KITTI split, prediction folders against ground truth.

Every score goes through :class:`~semattnet.evaluation.metrics.KittiMetrics` (the devkit's rule).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import DataLoader, Subset

from semattnet._errors import InputError
from semattnet._utils import distributed as dist_utils
from semattnet._utils.device import autocast
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs, write_text
from semattnet._utils.progress import progress as progress_bar
from semattnet.data.datasets import get_dataset
from semattnet.data.frames import Frame
from semattnet.data.io import DataError, clamp_for_png, quantize_depth, read_depth
from semattnet.data.kitti import KittiDepthCompletion
from semattnet.data.sources.kitti_split import prediction_name
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.evaluation.sparsification import Sparsification
from semattnet.evaluation.split import eval_dataset, prepare_out, refuse_listed_inputs
from semattnet.inference.completer import Completion, DepthCompleter
from semattnet.inference.padding import crop_padding
from semattnet.inference.pipeline import write_prediction
from semattnet.inference.sharding import agree, gather_rows, on_main, process_group, shared_stage
from semattnet.inference.sinks import DepthPngSink, PanelSink, Sink, output_files
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.uncertainty import with_uncertainty
from semattnet.palette import check_palette

__all__ = ["PredictionWriter", "evaluate_checkpoint", "evaluate_model", "score_folders", "score_folders_to_json"]

#: The sparsification curves' picture in ``evaluate``'s output folder.
SPARSIFICATION_PNG = "sparsification.png"


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
    for name in progress_bar(sorted(gts), desc="scoring", enabled=progress, leave=False):
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
    metrics: Callable[[], KittiMetrics] | None = None,
) -> KittiMetrics:
    """Score ``model`` over ``loader`` (batches from :class:`KittiDepthCompletion`), all ranks.

    ``metrics``: a fresh accumulator of the dataset's protocol (default :class:`KittiMetrics`, the devkit's).
    Items that carry a ``pad`` (padded to the model's multiple of 32 by
    :class:`~semattnet.data.datasets.frames.FrameDataset`) are scored and written on the crop without it.

    ``quantize`` scores what a KITTI 16-bit PNG of the prediction holds (clamped, 1/256 m steps,
    holes kept as 0 for the devkit to fill), i.e. exactly what ``semattnet metrics`` and the benchmark see.
    """
    scores = _score_local(model, loader, device, amp, progress, on_batch, fill_holes, min_gt, quantize, metrics)
    scores.reduce()
    return scores
    return metrics


def _score_local(model: nn.Module, loader: DataLoader, device: torch.device, amp: str, progress: bool,
                 on_batch: Callable[[dict[str, Any], Any], None] | None, fill_holes: bool, min_gt: float,
                 quantize: bool, make_metrics: Callable[[], KittiMetrics] | None = None,
                 sparsification: Sparsification | None = None) -> KittiMetrics:  # fmt: skip
    """:func:`evaluate_model` on this rank's batches only (no collective); with ``sparsification``, each
    output also gets its ``uncertainty`` (:func:`~semattnet.models.uncertainty.with_uncertainty`), scored there."""
    metrics = make_metrics() if make_metrics is not None else KittiMetrics(fill_holes=fill_holes, min_gt=min_gt)
    was_training = model.training
    model.eval()
    with torch.inference_mode():
        for batch in progress_bar(loader, desc="evaluating", enabled=progress and dist_utils.is_main(), leave=False):
            x = {k: batch[k].to(device, non_blocking=True) for k in ("rgb", "semantic", "sparse")}
            with autocast(device, amp):
                out = model(**x)
            if "pad" in batch:  # padded to multiples of 32 by the dataset: score and write the protocol's crop
                out, batch = _unpad(out, batch)
            scored = sparsification is not None and isinstance(out, DepthCompletionOutput)
            if scored:
                out = with_uncertainty(out.map(lambda t: t.float()), batch["sparse"].to(device))
            if "gt" in batch:
                pred = out.depth.float()
                if quantize:
                    pred = _as_png(pred, list(batch["name"]))
                metrics.update(pred, batch["gt"].to(device), names=list(batch["name"]))
                if scored and sparsification is not None and out.uncertainty is not None:
                    for p, g, u in zip(pred, batch["gt"].to(device), out.uncertainty, strict=True):
                        sparsification.add(p[0], g[0], u[0])
            if on_batch is not None:
                on_batch(batch, out)
    model.train(was_training)
    return metrics


def _unpad(out: Any, batch: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """Outputs and images of a batch whose items carry their ``pad`` (top, bottom, left, right), cropped back."""
    top, bottom, left, right = (int(v) for v in batch["pad"][0].tolist())
    pad = (top, bottom, left, right)
    if not any(pad):
        return out, batch
    crop = partial(crop_padding, pad=pad)
    images = {k: crop(batch[k]) for k in ("rgb", "semantic", "sparse", "gt") if k in batch}
    return out.map(crop), batch | images


def _as_png(pred: torch.Tensor, names: list[str]) -> torch.Tensor:
    """What the 16-bit PNGs of (B, 1, H, W) predictions hold: :func:`clamp_for_png`, then the one quantiser."""
    return torch.stack([quantize_depth(clamp_for_png(p, name)) for p, name in zip(pred, names, strict=True)])


def score_folders_to_json(pred_dir: str | Path, gt_dir: str | Path, json_path: str | Path | None = None,
                          overwrite: bool = False, fill_holes: bool = True,
                          min_gt: float = 0.0) -> KittiMetrics:  # fmt: skip
    """:func:`score_folders`, then (optionally) the metrics as JSON in ``json_path``: never an input
    file, never replacing an existing file unless ``overwrite`` (both checked before scoring)."""
    if json_path is not None:
        check_no_input_overlap([pred_dir, gt_dir], out_files=[json_path])
        check_outputs([("PRED", pred_dir), ("GT", gt_dir)], [Output("--json", json_path, "json")], overwrite)
    metrics = score_folders(pred_dir, gt_dir, fill_holes=fill_holes, min_gt=min_gt)
    if json_path is not None:
        write_text(json_path, json.dumps(metrics.compute(), indent=2) + "\n", overwrite=overwrite)
    return metrics


class PredictionWriter:
    """``on_batch`` callback of :func:`evaluate_model`: each frame of the batch, as a
    :class:`~semattnet.data.frames.Frame` with its typed result, through the one writer
    (:func:`semattnet.inference.pipeline.write_prediction`) into the sinks: ``predictions/`` (16-bit PNGs
    named like the ground truth for val_select) and the panels of the first ``pictures`` frames in
    ``pictures/NAME.png``."""

    def __init__(self, ds: KittiDepthCompletion, split: str, out: Path, save_predictions: bool, pictures: int,
                 frames: int | None = None) -> None:  # fmt: skip
        todo = ds.frames[: len(ds.frames) if frames is None else frames]
        self.ds, self.out = ds, out
        self.sinks: list[Sink] = []
        if save_predictions:
            rename = {f.name: prediction_name(split, f) for f in todo}
            self.sinks.append(DepthPngSink(folder="predictions", rename=rename))
        if pictures:
            self.sinks.append(PanelSink(suffix=".png", folder="pictures", only={f.name for f in todo[:pictures]}))

    def expected(self, frames: int) -> list[str]:
        """The files written for the first ``frames`` frames, relative to ``out``."""
        return output_files([f.name for f in self.ds.frames[:frames]], self.sinks)

    def __call__(self, batch: dict[str, Any], result: Any) -> None:
        for i, idx in enumerate(batch["index"].tolist()):
            frame = self.ds.frames[idx]
            if not any(sink.path(frame.name) for sink in self.sinks):
                continue
            write_prediction(self.out, _frame(batch, i, frame.name), _completion(result, i), self.sinks)


def _frame(batch: dict[str, Any], i: int, name: str) -> Frame:
    """Item ``i`` of a :class:`KittiDepthCompletion` batch as a :class:`Frame` (images back to uint8)."""
    rgb, sem = (batch[k][i].permute(1, 2, 0).clamp(0, 255).round().byte().numpy() for k in ("rgb", "semantic"))
    gt = batch["gt"][i, 0].float().numpy() if "gt" in batch else None
    return Frame(name, rgb, batch["sparse"][i, 0].float().numpy(), sem, gt=gt)


def _completion(result: Any, i: int) -> Completion:
    """Item ``i`` of a batched model result as a :class:`Completion` (typed when the model's output is)."""
    depth = result.depth[i, 0].float().cpu().numpy()
    if isinstance(result, DepthCompletionOutput):
        return Completion(depth, result.map(lambda t: t[i : i + 1].float().cpu()))
    return Completion(depth)


def _write_scores(out: Path, metrics: KittiMetrics, summary: dict[str, Any], spars: Sparsification) -> list[str]:
    """``metrics.json`` (the summary), ``per_image.csv`` (one row per frame) and, when the uncertainty was
    scored, ``sparsification.png`` (its curves, :func:`semattnet.viz.curves.plot_sparsification`), written
    by rank 0 only. Returns their names (every rank)."""
    names = ["metrics.json", "per_image.csv", *([SPARSIFICATION_PNG] if spars.frames else [])]
    if not dist_utils.is_main():
        return names
    (out / "metrics.json").write_text(json.dumps(summary, indent=2) + "\n")
    if spars.frames:
        from semattnet.evaluation.sparsification import figure_data
        from semattnet.viz.curves import plot_sparsification

        label = Path(str(summary.get("checkpoint", "model"))).name
        plot_sparsification({label: figure_data(spars.curves())}, out / SPARSIFICATION_PNG)
    with open(out / "per_image.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(metrics.per_image[0]))
        writer.writeheader()
        writer.writerows(metrics.per_image)
    return names


def evaluate_checkpoint(
    checkpoint: str | Path | nn.Module | Callable[[], nn.Module],
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
    dataset: str = "kitti-dc",
    palette_mismatch: str = "refuse",
) -> dict[str, Any]:
    """Run a checkpoint (a path, a loaded model, or a function that loads one: called after the split
    and the output folder are checked) over a split and score it; optionally write predictions and
    panels (through :mod:`semattnet.inference.sinks`). ``backend`` chooses the inference engine
    (:func:`semattnet.inference.backends.optimize_for_inference`; fixed-size backends are built for
    the split's frame size).

    Writes into ``out_dir``: ``metrics.json``, ``per_image.csv``, ``predictions/`` (16-bit PNGs named
    like the ground truth for val_select) and ``pictures/`` (branch panels of the first frames); the
    uncertainty's AUSE / AURG (:mod:`semattnet.evaluation.sparsification`) and ``sparsification.png``.

    Under ``torchrun`` (same arguments on every rank; ``cuda:LOCAL_RANK`` on GPUs) rank ``r`` of ``W``
    scores frames ``r, r + W, ...`` (each frame once); the metrics are summed over the ranks and the
    per-image rows gathered in the split's order, so the files are those of one process.

    ``dataset``: the protocol (:mod:`semattnet.data.datasets`: ``kitti-dc``, ``nyuv2``, ``void``): its split,
    metrics and palette: maps of another palette than the model's are refused unless ``palette_mismatch`` is
    ``recolour`` / ``fallback`` (nyuv2, void; :class:`~semattnet.data.sources.semantic.CrossPaletteSource`)."""
    inputs = [data, raw_root, semantic_root, checkpoint if isinstance(checkpoint, str | Path) else None]
    with process_group():
        ds, frames, out = _plan(data, split, raw_root, semantic_root, max_frames, out_dir, overwrite, inputs, dataset)
        completer, label = _completer(checkpoint, device, amp, backend)  # after every check
        spec, semantic = _check_maps(completer, ds, data, dataset, palette_mismatch)
        loader = DataLoader(Subset(ds, range(frames)), batch_size=batch_size, num_workers=workers,
                            sampler=dist_utils.ShardSampler(frames))  # fmt: skip
        engine = completer.engine(tuple(ds[0]["rgb"].shape[-2:])) if frames else completer.model
        spars = Sparsification()
        score = partial(_score_local, engine, loader, completer.device, amp, True, fill_holes=True, min_gt=0.0,
                        quantize=True, make_metrics=spec.metrics, sparsification=spars)  # fmt: skip
        if out is None:
            metrics = _merge(agree(score, None), ds, spars)
            return {"metrics": metrics, "result": _result(metrics, spars), "sparsification": spars, **semantic}
        writer = PredictionWriter(ds, split, out, save_predictions, pictures, frames)
        expected = writer.expected(frames)
        with shared_stage(out, overwrite, expected) as stage:  # all files appear together, or none
            writer.out = stage
            metrics = _merge(agree(score, writer), ds, spars)
            result = _result(metrics, spars)
            if result:
                expected += _write_scores(stage, metrics, {"checkpoint": label, "dataset": spec.name,
                                                           "split": split, **semantic} | result, spars)  # fmt: skip
    return {"metrics": metrics, "result": result, "sparsification": spars, **semantic}


def _result(metrics: KittiMetrics, spars: Sparsification) -> dict[str, Any]:
    """The metrics (empty without any frame with ground truth) and the uncertainty's AUSE / AURG
    (:mod:`semattnet.evaluation.sparsification`: ``ause_rmse``, ``aurg_rmse``, ``ause_mae``, ``aurg_mae``)."""
    return (metrics.compute() | spars.compute()) if metrics.per_image else {}


def _check_maps(completer: DepthCompleter, ds: Any, data: str | Path, dataset: str,
                mismatch: str = "refuse") -> tuple[Any, dict[str, Any]]:  # fmt: skip
    """The dataset's entry, once its maps' palette is the model's (a dataset without maps: any), and ``{}``;
    with another palette and ``mismatch`` ``recolour`` / ``fallback``: ``ds`` reads them converted, and
    ``{"semantic": what they became}``."""
    from semattnet.palette import get_palette

    spec, palette = get_dataset(dataset), getattr(ds, "palette", "cityscapes")
    if not (completer.needs_semantic and palette) or get_palette(palette).name == get_palette(completer.palette).name:
        return spec, {}
    if mismatch == "refuse":
        check_palette(completer.palette, palette, f"{data} ({spec.name} maps)")
    if not hasattr(ds, "source"):
        raise InputError(f"--palette-mismatch {mismatch}: only for nyuv2 and void (not {spec.name})")
    from semattnet.data.sources.semantic import CrossPaletteSource

    ds.source = CrossPaletteSource(ds.source, completer.palette, mismatch)
    ds.palette = ds.source.palette
    return spec, {"semantic": ds.source.report()}


def _plan(data: str | Path, split: str, raw_root: str | Path | None, semantic_root: str | Path | None,
          max_frames: int | None, out_dir: str | Path | None, overwrite: bool,
          inputs: list[Any], dataset: str = "kitti-dc") -> tuple[KittiDepthCompletion, int, Path | None]:  # fmt: skip
    """Every check before the model is loaded: the output folder (rank 0), the split indexed and the
    frames to score decoded (each rank its share). Returns the dataset, the frame count and ``out``."""
    out = on_main(prepare_out, Path(out_dir), overwrite, inputs) if out_dir is not None else None
    ds = eval_dataset(data, split, raw_root, semantic_root, dataset)
    refuse_listed_inputs(out, ds)
    frames = min(len(ds), max_frames) if max_frames else len(ds)
    agree(lambda: [ds.load(i) for i in dist_utils.ShardSampler(frames)])
    return ds, frames, out


def _completer(checkpoint: str | Path | nn.Module | Callable[[], nn.Module], device: str, amp: str,
               backend: str) -> tuple[DepthCompleter, str]:  # fmt: skip
    """The completer (on ``cuda:LOCAL_RANK`` under torchrun with CUDA) and how metrics.json names it;
    ``checkpoint`` may be a function that loads the model (called only now, after every check)."""
    device_ = dist_utils.process_device(device)
    if isinstance(checkpoint, str | Path):
        return DepthCompleter.from_checkpoint(checkpoint, device=device_, amp=amp, backend=backend), str(checkpoint)
    model = checkpoint if isinstance(checkpoint, nn.Module) else checkpoint()
    label = getattr(checkpoint, "label", None) or type(model).__name__
    return DepthCompleter(model, device=device_, amp=amp, backend=backend), str(label)


def _merge(metrics: KittiMetrics, ds: KittiDepthCompletion, spars: Sparsification) -> KittiMetrics:
    """``metrics`` and ``spars`` summed over the ranks, with every rank's per-image rows in the split's order
    (collective)."""
    metrics.reduce()
    spars.reduce()
    position = {frame.name: i for i, frame in enumerate(ds.frames)}
    metrics.per_image = gather_rows(metrics.per_image, key=lambda row: position[str(row["name"])])
    return metrics
