"""Prediction and pictures for a user's frames: ``predict``, ``visualize``."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._group import main


@main.command()
@click.option(
    "--checkpoint",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Model weights (not needed with --method classical).",
)
@click.option("--rgb", required=True, type=click.Path(exists=True, path_type=Path), help="PNG file or folder.")
@click.option(
    "--sparse", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder."
)
@click.option("--semantic", type=click.Path(exists=True, path_type=Path), default=None, help="PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--npy", is_flag=True, help="Also write float32 .npy depth.")
@click.option("--panel", is_flag=True, help="Also write the per-branch panel.")
@click.option("--device", default="auto", show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@click.option("--overwrite", is_flag=True, help="Replace existing outputs.")
@click.option(
    "--method",
    type=click.Choice(["semattnet", "classical"]),
    default="semattnet",
    show_default=True,
    help="classical: the non-learned IP-Basic-style baseline (no checkpoint).",
)
def predict(checkpoint: Path | None, rgb: Path, sparse: Path, semantic: Path | None, out: Path, npy: bool, panel: bool,
            device: str, amp: str, overwrite: bool, method: str) -> None:  # fmt: skip
    """Complete depth for one frame or folders of frames (any size)."""
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.data.pairing import pair_frames
    from semattnet.inference import DepthCompleter, complete_folder

    if method == "semattnet" and checkpoint is None:
        raise click.UsageError("--checkpoint is required (or --method classical)")
    frames = pair_frames(rgb, sparse, semantic)
    if method == "semattnet":
        completer = DepthCompleter.from_checkpoint(checkpoint, device=device, amp=amp)
    else:
        completer = ClassicalCompleter()
    complete_folder(completer, frames, out, npy=npy, panel=panel, overwrite=overwrite, log=click.echo)


@main.command()
@click.option("--pred", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--gt", type=click.Path(exists=True, path_type=Path), default=None, help="Ground truth: adds error maps.")
@click.option("--vmax", default=80.0, show_default=True, help="Depth of the colour scale's top, metres.")
def visualize(pred: Path, out: Path, gt: Path | None, vmax: float) -> None:
    """Colourise saved depth predictions (and error maps against ground truth)."""
    from semattnet.viz.depth import write_depth_pictures

    count = write_depth_pictures(pred, out, gt, vmax)
    click.echo(f"wrote {count} picture(s) to {out}")
