"""Scoring: a completer over a dataset's split through the one frame loop, prediction folders against ground truth.

Every score goes through the protocol's metrics (:mod:`semattnet.evaluation.protocols`; KITTI's
:class:`~semattnet.evaluation.metrics.KittiMetrics`, the devkit's rule).
"""

from __future__ import annotations

import csv
import json
import os
import tempfile
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import torch

from semattnet._errors import InputError
from semattnet._utils import distributed as dist_utils
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs, write_text
from semattnet._utils.progress import progress as progress_bar
from semattnet.data.datasets import get_dataset
from semattnet.data.frames import IndexedSource
from semattnet.data.io import DataError, read_depth
from semattnet.data.sources.semantic import PaletteReport
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.evaluation.protocols import eval_source, protocol_metrics
from semattnet.evaluation.sink import MetricsSink
from semattnet.evaluation.sparsification import Sparsification
from semattnet.evaluation.split import prepare_out, refuse_listed_inputs
from semattnet.inference.contract import CompleterFactory
from semattnet.inference.journal import FRAMES_FILE
from semattnet.inference.pipeline import Completer, OutputSpec, RunOptions, check_frames
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sharding import gather_rows, on_main, process_group, shared_stage
from semattnet.inference.sinks import ColorPngSink, DepthPngSink, PanelSink, Sink, output_files

__all__ = [
    "SPARSIFICATION_PNG",
    "EvalOutputs",
    "EvalSplit",
    "Evaluation",
    "evaluate_split",
    "resolve_completer",
    "score_folders",
    "score_folders_to_json",
]

PathLike = str | os.PathLike[str]
#: The sparsification curves' picture in ``evaluate``'s output folder.
SPARSIFICATION_PNG = "sparsification.png"


def _previews(folder: Path) -> set[Path]:
    """The pictures ``predict`` writes beside a depth PNG ``NAME.png`` (``NAME_color.png``, ``NAME_panel.png``):
    not predictions."""
    suffixes = (ColorPngSink.suffix, PanelSink.suffix)
    return {
        p
        for p in folder.glob("*.png")
        for s in suffixes
        if p.name.endswith(s) and (folder / (p.name.removesuffix(s) + ".png")).is_file()
    }


def _pngs_by_key(folder: Path, skip: Collection[Path] = ()) -> dict[str, Path]:
    """The PNGs of ``folder`` (but ``skip``) by the name that pairs them
    (:func:`~semattnet.data.kitti.layout.selection_key`: a KITTI selection image or scan is keyed as its ground
    truth); two files of one frame are refused."""
    from semattnet.data.kitti.layout import selection_key

    found: dict[str, Path] = {}
    for p in sorted(p for p in folder.glob("*.png") if p not in skip):
        key = selection_key(p.name)
        if key in found:
            raise DataError(f"{folder}: {found[key].name} and {p.name} are predictions of one KITTI frame; keep one")
        found[key] = p
    return found


def _pairs(pred: Path, gt: Path) -> dict[str, tuple[Path, Path]]:
    """(prediction, ground truth) by the ground truth's name: two files (one pair), or two folders paired by
    name (KITTI's selection names ``_image_`` / ``_velodyne_raw_`` with ``_groundtruth_depth_``)."""
    if pred.is_file() and gt.is_file():
        return {gt.name: (pred, gt)}
    if pred.is_dir() != gt.is_dir() or not pred.is_dir():
        kinds = " and ".join(
            f"{p} is {'a folder' if p.is_dir() else 'a file' if p.is_file() else 'neither'}" for p in (pred, gt)
        )
        raise DataError(f"PRED and GT must be two PNG files or two folders: {kinds}")
    preds, gts = _pngs_by_key(pred, _previews(pred)), _pngs_by_key(gt)
    if not gts:
        raise DataError(f"{gt}: no PNG files")
    if preds.keys() != gts.keys():
        only_p = sorted(preds[k].name for k in preds.keys() - gts.keys())
        only_g = sorted(gts[k].name for k in gts.keys() - preds.keys())
        raise DataError(
            f"{pred} has {len(preds)} files, {gt} {len(gts)}; "
            f"without ground truth: {only_p[:5]}{' ...' if len(only_p) > 5 else ''}; "
            f"without prediction: {only_g[:5]}{' ...' if len(only_g) > 5 else ''}"
        )
    return {gts[k].name: (preds[k], gts[k]) for k in gts}


def score_folders(
    pred_dir: str | Path, gt_dir: str | Path, fill_holes: bool = True, min_gt: float = 0.0, progress: bool = True
) -> KittiMetrics:
    """Score 16-bit PNG predictions against ground truth: one pair of files, or two folders whose files pair by
    name (a KITTI selection prediction named like its image, ``..._image_...``, pairs with
    ``..._groundtruth_depth_...``).

    Raises:
        DataError: the folders hold different frames (listed), a pair differs in size, or a file meets a folder.
    """
    pairs = _pairs(Path(pred_dir), Path(gt_dir))
    metrics = KittiMetrics(fill_holes=fill_holes, min_gt=min_gt)
    bad = []
    for name in progress_bar(sorted(pairs), desc="scoring", enabled=progress, leave=False):
        pred, gt = (read_depth(p) for p in pairs[name])
        if pred.shape != gt.shape:
            bad.append(
                f"{name}: prediction {pred.shape[1]}x{pred.shape[0]} vs ground truth {gt.shape[1]}x{gt.shape[0]}"
            )
            continue
        metrics.update(torch.from_numpy(pred)[None, None], torch.from_numpy(gt)[None, None], names=[name])
    if bad:
        raise DataError(f"size mismatch in {len(bad)} pair(s): " + "; ".join(bad[:5]))
    return metrics


def score_folders_to_json(
    pred_dir: str | Path,
    gt_dir: str | Path,
    json_path: str | Path | None = None,
    overwrite: bool = False,
    fill_holes: bool = True,
    min_gt: float = 0.0,
) -> KittiMetrics:
    """:func:`score_folders`, then (optionally) the metrics as JSON in ``json_path``: never an input
    file, never replacing an existing file unless ``overwrite`` (both checked before scoring)."""
    if json_path is not None:
        check_no_input_overlap([pred_dir, gt_dir], out_files=[json_path])
        check_outputs([("PRED", pred_dir), ("GT", gt_dir)], [Output("--json", json_path, "json")], overwrite)
    metrics = score_folders(pred_dir, gt_dir, fill_holes=fill_holes, min_gt=min_gt)
    if json_path is not None:
        write_text(json_path, json.dumps(metrics.compute(), indent=2) + "\n", overwrite=overwrite)
    return metrics


@dataclass
class Evaluation:
    """What :func:`evaluate_split` found: ``metrics`` (every rank's, reduced; ``per_image`` rows in the split's order),
    ``result`` (the metrics and the uncertainty's AUSE / AURG; empty without any frame with ground truth),
    ``sparsification`` (its curves) and ``semantic`` (what maps of another palette became, or None)."""

    metrics: KittiMetrics
    result: dict[str, float] = field(default_factory=dict)
    sparsification: Sparsification = field(default_factory=Sparsification)
    semantic: PaletteReport | None = None


@dataclass(frozen=True)
class EvalSplit:
    """The frames :func:`evaluate_split` scores: ``split`` (default: the dataset's evaluation split) of ``dataset``
    (the registry entry, :mod:`semattnet.data.datasets`: ``kitti-dc``, ``nyuv2``, ``void``) under ``data``, its
    first ``max_frames`` frames (None: all; :func:`~.protocols.eval_source`), with the raw drives and semantic
    maps of separate roots; ``palette_mismatch``: what a semantic map of another palette becomes
    (:class:`~semattnet.inference.semantic.SemanticMaps`)."""

    data: PathLike
    split: str | None = None
    dataset: str = "kitti-dc"
    max_frames: int | None = None
    raw_root: PathLike | None = None
    semantic_root: PathLike | None = None
    palette_mismatch: str = "refuse"


@dataclass(frozen=True)
class EvalOutputs:
    """What :func:`evaluate_split` writes into its output folder besides the scores: ``predictions/``
    (``save_predictions``), the panels of the first ``pictures`` frames; ``overwrite`` an existing folder;
    ``label``: ``metrics.json``'s ``checkpoint`` (the model's class by default); ``inputs``: further files (the
    weights) that outputs must stay out of."""

    save_predictions: bool = False
    pictures: int = 0
    overwrite: bool = False
    label: str | None = None
    inputs: Sequence[PathLike | None] = ()


def evaluate_split(
    completer: Completer | CompleterFactory,
    frames: EvalSplit,
    out_dir: PathLike | None = None,
    outputs: EvalOutputs | None = None,
    options: RunOptions | None = None,
) -> Evaluation:
    """Complete a split with ``completer`` through the one frame loop
    (:func:`~semattnet.inference.pipeline.complete_frames`) and score it with the dataset's metrics
    (:class:`~.sink.MetricsSink`); optionally write predictions and panels.

    ``completer``: a :class:`~semattnet.inference.DepthCompleter` (or any
    :class:`~semattnet.inference.pipeline.Completer`, e.g. :class:`~semattnet.baselines.ClassicalCompleter`), or
    a :class:`~semattnet.inference.contract.CompleterFactory`, built only after every input and output check.
    ``frames``: the split (:class:`EvalSplit`); ``outputs``: :class:`EvalOutputs`; ``options``: the
    loop's ``batch_size`` and ``prefetch`` (:class:`~semattnet.inference.options.RunOptions`; a faulty frame stops
    the run, and every frame is scored: no real-time replay).

    Writes into ``out_dir``, all together or nothing: ``metrics.json``, ``per_image.csv``, ``predictions/``
    (16-bit PNGs named like the ground truth for val_select), ``pictures/`` (panels of the first ``pictures``
    frames) and ``sparsification.png`` (the uncertainty's curves; AUSE / AURG in ``metrics.json``).

    Under ``torchrun`` (same arguments on every rank) each rank completes its share of the frames; metrics are
    summed over the ranks and per-image rows gathered in the split's order: the files of one process."""
    outputs, loop = outputs or EvalOutputs(), _loop_options(options or RunOptions())
    with process_group():
        spec = get_dataset(frames.dataset)
        split = spec.check_split(frames.split)
        given = [frames.data, frames.raw_root, frames.semantic_root, *outputs.inputs]
        out = on_main(prepare_out, Path(out_dir), outputs.overwrite, given) if out_dir is not None else None
        source = eval_source(
            spec,
            frames.data,
            split,
            raw_root=frames.raw_root,
            semantic_root=frames.semantic_root,
            max_frames=frames.max_frames,
        )
        refuse_listed_inputs(out, source)
        scores = MetricsSink(metrics=protocol_metrics(spec))
        sinks = [*(_file_sinks(source, outputs.save_predictions, outputs.pictures) if out is not None else []), scores]
        expected = output_files(source.names, sinks)
        with _stage(out, outputs.overwrite, expected) as stage:
            plan = check_frames(source, sinks, stage, OutputSpec(overwrite=True, inputs=given), loop)
            model = resolve_completer(completer, "evaluate")  # after every check
            maps = SemanticMaps(mismatch=frames.palette_mismatch)
            plan.run(model, semantic=maps, log=_quiet)
            on_main(_forget_journal, stage)  # the output is all or nothing: no frame to resume
            semantic = maps.cross.report() if maps.cross is not None else None
            res = _merge(scores, source, semantic)
            if out is not None and res.result:  # metrics.json's keys as before: "checkpoint" names the model
                head = {"checkpoint": outputs.label or type(model).__name__, "dataset": spec.name, "split": split}
                expected += _write_scores(stage, res, head | ({"semantic": semantic} if semantic else {}))
    return res


def _loop_options(options: RunOptions) -> RunOptions:
    """The loop's options for a scored run: ``options``' batches and read-ahead; the first faulty frame stops it."""
    if options.realtime is not None:
        raise InputError("evaluate: every frame is scored; a real-time replay (RunOptions.realtime) would drop some")
    return replace(options, on_error="stop")


def resolve_completer(completer: Completer | CompleterFactory, command: str = "evaluate") -> Completer:
    """``completer``, or the one a :class:`~semattnet.inference.contract.CompleterFactory` builds: what
    :func:`evaluate_split`, the sparsity sweep and the submission accept, resolved after every check."""
    if isinstance(completer, CompleterFactory):
        return completer.build()
    if callable(completer):
        return completer
    raise InputError(f"{command}: {completer!r} is neither a completer (rgb, sparse, semantic) nor a CompleterFactory")


def _quiet(line: str) -> None:
    """The loop's per-frame lines are not printed: ``evaluate`` reports the metrics."""


@contextmanager
def _stage(out: Path | None, overwrite: bool, expected: list[str]) -> Iterator[Path]:
    """Where the loop writes: the shared stage of ``out`` (moved into place when every rank succeeded, with
    every ``expected`` file), or a scratch folder of this process without ``out``."""
    if out is None:
        with tempfile.TemporaryDirectory(prefix="semattnet-evaluate.") as scratch:
            yield Path(scratch)
        return
    with shared_stage(out, overwrite, expected) as stage:
        yield stage


def _forget_journal(stage: Path) -> None:
    for path in (stage / FRAMES_FILE, *stage.glob(".frames.rank*.json")):
        path.unlink(missing_ok=True)


def _file_sinks(source: IndexedSource, save_predictions: bool, pictures: int) -> list[Sink]:
    """``predictions/`` (named by the source: the ground truth's name for KITTI's val_select) and the panels of
    the first ``pictures`` frames in ``pictures/NAME.png``."""
    sinks: list[Sink] = []
    if save_predictions:
        info = source.info
        rename = {n: info.prediction_name(n) for n in source.names}
        sinks.append(DepthPngSink(folder="predictions", rename=rename))
    if pictures:
        sinks.append(PanelSink(suffix=".png", folder="pictures", only=set(source.names[:pictures])))
    return sinks


def _merge(scores: MetricsSink, source: IndexedSource, semantic: PaletteReport | None) -> Evaluation:
    """The sink's metrics and curves summed over the ranks, with every rank's per-image rows in the split's
    order (collective), and the result: the metrics and the uncertainty's AUSE / AURG
    (:mod:`semattnet.evaluation.sparsification`)."""
    metrics, spars = scores.metrics, scores.sparsification
    metrics.reduce()
    spars.reduce()
    position = {name: i for i, name in enumerate(source.names)}
    metrics.per_image = gather_rows(metrics.per_image, key=lambda row: position[str(row["name"])])
    result = (metrics.compute() | spars.compute()) if metrics.per_image else {}
    return Evaluation(metrics, result, spars, semantic)


def _write_scores(out: Path, res: Evaluation, summary: Mapping[str, object]) -> list[str]:
    """``metrics.json`` (the summary), ``per_image.csv`` (one row per frame) and, when the uncertainty was
    scored, ``sparsification.png`` (its curves, :func:`semattnet.viz.curves.plot_sparsification`), written
    by rank 0 only. Returns their names (every rank)."""
    spars = res.sparsification
    names = ["metrics.json", "per_image.csv", *([SPARSIFICATION_PNG] if spars.frames else [])]
    if not dist_utils.is_main():
        return names
    (out / "metrics.json").write_text(json.dumps({**summary, **res.result}, indent=2) + "\n")
    if spars.frames:
        from semattnet.evaluation.sparsification import figure_data
        from semattnet.viz.curves import plot_sparsification

        plot_sparsification(
            {Path(str(summary["checkpoint"])).name: figure_data(spars.curves())}, out / SPARSIFICATION_PNG
        )
    with open(out / "per_image.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(res.metrics.per_image[0]))
        writer.writeheader()
        writer.writerows(res.metrics.per_image)
    return names
