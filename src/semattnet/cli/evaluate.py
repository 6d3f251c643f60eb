"""Scoring commands: ``metrics``, ``evaluate``, ``submit``."""

from __future__ import annotations

import os
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import click

from semattnet.cli._dataset import dataset_option
from semattnet.cli._group import main
from semattnet.cli._model import ModelOptions, model_options, palette_mismatch_option
from semattnet.cli._options import (
    BATCH_SIZE,
    COUNT,
    DEPTH_M_OR_ZERO,
    POSITIVE_INT,
    WORKERS,
)
from semattnet.cli._params import values_of, with_options

if TYPE_CHECKING:
    from semattnet.evaluation.evaluate import Evaluation


@main.command()
@click.argument("pred_dir", metavar="PRED", type=click.Path(exists=True, path_type=Path))
@click.argument("gt_dir", metavar="GT", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the metrics as JSON.",
)
@click.option(
    "--min-gt",
    type=DEPTH_M_OR_ZERO,
    default=0.0,
    show_default=True,
    help="Count gt > this (0.1 = the authors' variant).",
)
@click.option("--no-fill", is_flag=True, help="Do not fill prediction holes (the devkit fills them).")
@click.option("--overwrite", is_flag=True, help="Replace an existing --json file.")
def metrics(
    pred_dir: Path, gt_dir: Path, json_path: Path | None, min_gt: float, no_fill: bool, overwrite: bool
) -> None:
    """Score 16-bit PNG depth predictions against ground truth (KITTI devkit metrics).

    PRED and GT: two folders whose PNGs pair by name (KITTI selection names too: a prediction named like its
    ``..._image_...`` image pairs with ``..._groundtruth_depth_...``), or two files (one frame)."""
    from semattnet.evaluation.evaluate import score_folders_to_json

    m = score_folders_to_json(pred_dir, gt_dir, json_path, overwrite, fill_holes=not no_fill, min_gt=min_gt)
    click.echo(m.table())


@main.command()
@model_options()
@click.option("--data", "data_root", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@dataset_option("The dataset and its protocol (split, crop, depth range, metrics).")
@click.option(
    "--split",
    type=click.Choice(["val_select", "val", "test"]),
    default=None,
    help="[val_select for kitti-dc; test for nyuv2 and void]",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for metrics.json, per_image.csv, predictions/ and pictures/ (or the sparsity sweep's files).",
)
@click.option(
    "--sparsity",
    "sparsity",
    multiple=True,
    metavar="beams=64,32,..|keep=1,0.5,..",
    help="Sweep sparser inputs (repeatable): the model and the classical baseline side by side; needs --out.",
)
@click.option(
    "--segment",
    default=None,
    metavar="SPEC",
    help="nyuv2 / void: semantic maps from this segmenter (e.g. hf:indoor; see `semattnet segment`), "
    "segmented once into a cache folder and reused.",
)
@with_options([palette_mismatch_option()])
@click.option("--save-predictions", is_flag=True, help="Write 16-bit PNG predictions (needs --out).")
@click.option(
    "--pictures", type=COUNT, default=0, show_default=True, help="Branch panels for the first N frames (needs --out)."
)
@click.option("--batch-size", type=BATCH_SIZE, default=1, show_default=True)
@click.option("--workers", type=WORKERS, default=2, show_default=True, help="Frames read ahead in a background thread.")
@click.option("--max-frames", type=POSITIVE_INT, default=None)
@click.option("--overwrite", is_flag=True)
def evaluate(
    data_root: Path,
    dataset: str,
    split: str | None,
    out: Path | None,
    sparsity: tuple[str, ...],
    segment: str | None,
    palette_mismatch: str,
    save_predictions: bool,
    pictures: int,
    batch_size: int,
    workers: int,
    max_frames: int | None,
    overwrite: bool,
    **params: object,
) -> None:
    """Evaluate weights (or a baseline: --method classical, --method prior) on a split with its dataset's metrics
    (KITTI: the devkit's), or sweep sparser inputs (--sparsity)."""
    model = values_of(ModelOptions, params)
    weights, method, device = model.weights, model.method, model.device
    split = _split(dataset, split)
    if sparsity and segment:
        raise click.UsageError("--segment is for the model's evaluation, not --sparsity")
    model.check_engine()
    if sparsity:
        if method == "prior":
            raise click.UsageError("--sparsity sweeps SemAttNet weights or --method classical, not --method prior")
        _one_process("evaluate --sparsity")
        if out is None:
            raise click.UsageError("--sparsity needs --out")
        _sweep(
            weights, data_root, split, out, sparsity, method, device, max_frames, overwrite, dataset, palette_mismatch
        )
        return
    from semattnet.evaluation.evaluate import EvalOutputs, EvalSplit, evaluate_split
    from semattnet.inference.contract import CompleterFactory
    from semattnet.inference.options import RunOptions

    if (save_predictions or pictures) and out is None:
        raise click.UsageError("--save-predictions and --pictures need --out")
    spec = _required_weights(weights) if method == "semattnet" else None
    if spec is None:
        model.check()  # a baseline: no weights (and --prior for the prior)
    semantic = None
    if segment is not None:
        from semattnet.segmentation.datasets import segment_split

        semantic = segment_split(dataset, data_root, (split,), segment, device, log=click.echo, max_frames=max_frames)
    local = Path(spec) if spec is not None and Path(spec).exists() else None
    label = spec or (f"prior {model.prior}" if method == "prior" else method)
    frames = EvalSplit(data_root, split, dataset, max_frames, semantic_root=semantic, palette_mismatch=palette_mismatch)
    outputs = EvalOutputs(save_predictions, pictures, overwrite, label=label, inputs=(local, model.calibration))
    options = RunOptions(prefetch=workers, batch_size=batch_size)
    res = evaluate_split(CompleterFactory(model.completer), frames, out, outputs, options)  # loaded after every check
    _report(res, out)


def _required_weights(weights: str | None) -> str:
    """``--weights`` (or its alias ``--checkpoint``), which the model's evaluation needs (a usage error)."""
    if weights is None:
        raise click.UsageError("--checkpoint or --weights is required (they are one option: --checkpoint is an alias)")
    return weights


def _report(res: Evaluation, out: Path | None) -> None:
    """The metrics table (and the uncertainty's scores), printed once: by rank 0 under torchrun."""
    from semattnet._utils.distributed import launch_rank

    if launch_rank() != 0:  # under torchrun: every rank holds the merged metrics; rank 0 reports them
        return
    if res.semantic is not None:
        click.echo(f"semantic maps: {res.semantic['summary']}")
    click.echo(res.metrics.table())
    r = res.result
    if "ause_rmse" in r:
        click.echo(
            f"uncertainty: AUSE RMSE {r['ause_rmse']:.4f}  MAE {r['ause_mae']:.4f}; "
            f"AURG RMSE {r['aurg_rmse']:.4f}  MAE {r['aurg_mae']:.4f} (docs/guides/uncertainty.md)"
        )
    if out is not None:
        click.echo(f"wrote {out / 'metrics.json'} and {out / 'per_image.csv'}")


def _split(dataset: str, split: str | None) -> str:
    """The split to score: the dataset's evaluation split by default; KITTI scores val_select or val only."""
    from semattnet.data.datasets import get_dataset

    spec = get_dataset(dataset)
    if dataset == "kitti-dc" and split == "test":
        raise click.BadParameter(
            "kitti-dc's test split has no ground truth (use `semattnet submit`)", param_hint="--split"
        )
    try:
        return spec.check_split(split)
    except ValueError as exc:  # InputError: the split is not the dataset's
        raise click.BadParameter(str(exc), param_hint="--split") from None


def _one_process(command: str) -> None:
    """Refuse to run ``command`` under torchrun with several processes (each would write the same files)."""
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        raise click.UsageError(f"{command} runs in one process; start it without torchrun")


def _sweep(
    weights: str | None,
    data_root: Path,
    split: str,
    out: Path,
    sparsity: tuple[str, ...],
    method: str,
    device: str,
    max_frames: int | None,
    overwrite: bool,
    dataset: str = "kitti-dc",
    palette_mismatch: str = "refuse",
) -> None:
    from semattnet.evaluation.sparsity import format_sweep, parse_settings, sweep_model
    from semattnet.weights.hub import load_model

    settings = parse_settings(sparsity)  # fail on a bad setting before loading anything
    if method == "classical" and weights is not None:
        raise click.UsageError("--method classical takes no --checkpoint / --weights")
    model = partial(load_model, _required_weights(weights)) if method == "semattnet" else None
    rows = sweep_model(
        data_root,
        split,
        settings,
        model,
        out,
        device,
        max_frames,
        overwrite,
        dataset=dataset,
        palette_mismatch=palette_mismatch,
    )
    click.echo(format_sweep(rows))
    click.echo(f"wrote {out / 'sparsity.csv'}, {out / 'sparsity.json'} and {out / 'sparsity.png'}")


@main.command()
@model_options(method=False)
@click.option("--data", "data_root", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Folder; OUT.zip is written too."
)
@click.option(
    "--expected-frames", type=COUNT, default=1000, show_default=True, help="0 accepts any count (synthetic data)."
)
@click.option("--overwrite", is_flag=True)
def submit(data_root: Path, out: Path, expected_frames: int, overwrite: bool, **params: object) -> None:
    """Predict the KITTI test split and write the zip to upload (checked before zipping)."""
    from semattnet.evaluation.submission import write_submission
    from semattnet.inference.contract import CompleterFactory

    _one_process("submit")
    model = ModelOptions(method="semattnet", **params)  # type: ignore[arg-type]
    weights = model.weights
    if weights is None:
        raise click.UsageError("give exactly one of --checkpoint or --weights (they are one option)")
    model.check_engine()
    completer = CompleterFactory(model.completer)  # loaded after every check
    local = Path(weights) if Path(weights).exists() else None  # a name or URL reads a cached download
    zip_path = write_submission(completer, data_root, out, expected_frames or None, overwrite, inputs=[local])
    click.echo(f"wrote {out} and {zip_path}")
