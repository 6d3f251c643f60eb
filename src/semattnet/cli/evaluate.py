"""Scoring commands: ``metrics``, ``evaluate``, ``submit``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from semattnet.cli._group import main


@main.command()
@click.argument("pred_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.argument("gt_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the metrics as JSON.",
)
@click.option("--min-gt", default=0.0, show_default=True, help="Count gt > this (0.1 = the authors' variant).")
@click.option("--no-fill", is_flag=True, help="Do not fill prediction holes (the devkit fills them).")
def metrics(pred_dir: Path, gt_dir: Path, json_path: Path | None, min_gt: float, no_fill: bool) -> None:
    """Score 16-bit PNG depth predictions against ground truth (KITTI devkit metrics)."""
    from semattnet.evaluation.evaluate import score_folders

    m = score_folders(pred_dir, gt_dir, fill_holes=not no_fill, min_gt=min_gt)
    click.echo(m.table())
    if json_path is not None:
        json_path.write_text(json.dumps(m.compute(), indent=2) + "\n")


@main.command()
@click.option("--checkpoint", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--data", "data_root", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--split", type=click.Choice(["val_select", "val"]), default="val_select", show_default=True)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for metrics.json, per_image.csv, predictions/ and pictures/.",
)
@click.option("--save-predictions", is_flag=True, help="Write 16-bit PNG predictions (needs --out).")
@click.option("--pictures", default=0, show_default=True, help="Branch panels for the first N frames (needs --out).")
@click.option("--device", default="auto", show_default=True)
@click.option("--batch-size", default=1, show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@click.option("--workers", default=2, show_default=True)
@click.option("--max-frames", type=int, default=None)
@click.option("--overwrite", is_flag=True)
def evaluate(checkpoint: Path, data_root: Path, split: str, out: Path | None, save_predictions: bool, pictures: int,
             device: str, batch_size: int, amp: str, workers: int, max_frames: int | None,
             overwrite: bool) -> None:  # fmt: skip
    """Evaluate a checkpoint on a KITTI (or synthetic) split with the official metrics."""
    from semattnet.evaluation.evaluate import evaluate_checkpoint

    if (save_predictions or pictures) and out is None:
        raise click.UsageError("--save-predictions and --pictures need --out")
    res = evaluate_checkpoint(checkpoint, data_root, split, out, device, batch_size, amp, workers,
                              save_predictions, pictures, max_frames, overwrite)  # fmt: skip
    click.echo(res["metrics"].table())
    if out is not None:
        click.echo(f"wrote {out / 'metrics.json'} and {out / 'per_image.csv'}")


@main.command()
@click.option("--checkpoint", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--data", "data_root", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Folder; OUT.zip is written too."
)
@click.option("--expected-frames", default=1000, show_default=True, help="0 accepts any count (synthetic data).")
@click.option("--device", default="auto", show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@click.option("--overwrite", is_flag=True)
def submit(checkpoint: Path, data_root: Path, out: Path, expected_frames: int, device: str, amp: str,
           overwrite: bool) -> None:  # fmt: skip
    """Predict the KITTI test split and write the zip to upload (checked before zipping)."""
    from semattnet.evaluation.submission import write_submission

    zip_path = write_submission(checkpoint, data_root, out, device, amp, expected_frames or None, overwrite)
    click.echo(f"wrote {out} and {zip_path}")
