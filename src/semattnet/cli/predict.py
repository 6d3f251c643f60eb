"""Prediction and pictures for a user's frames: ``predict``, ``visualize``."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._dataset import dataset_option
from semattnet.cli._group import main
from semattnet.cli._options import COUNT, POSITIVE_FLOAT, backend_option, weights_option


def _completer(method: str, checkpoint: Path | None, weights: str | None, device: str, amp: str,  # type: ignore[no-untyped-def]
               backend: str = "torch"):  # fmt: skip
    """The completer the options name: the classical baseline or the model of --checkpoint / --weights."""
    from semattnet._utils.distributed import process_device
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.cli._options import model_from_options
    from semattnet.inference import DepthCompleter

    if method == "classical":
        return ClassicalCompleter()
    _check_method(method, checkpoint, weights)
    model = model_from_options(checkpoint, weights, "cpu")
    return DepthCompleter(model, device=process_device(device), amp=amp, backend=backend, inplace=True)


def _check_method(method: str, checkpoint: Path | None, weights: str | None) -> None:
    """The model options agree (checked before any work)."""
    if method == "classical":
        return
    if checkpoint is None and weights is None:
        raise click.UsageError("--checkpoint or --weights is required (or --method classical)")
    if checkpoint is not None and weights is not None:
        raise click.UsageError("give --checkpoint or --weights, not both")


def _intrinsics(text: str | None):  # type: ignore[no-untyped-def]
    """--K as a (3, 3) matrix, or None."""
    from semattnet.viz.viewer import parse_intrinsics

    try:
        return parse_intrinsics(text) if text else None
    except ValueError:
        raise click.BadParameter(f"expected fx,fy,cx,cy or kitti, got {text!r}", param_hint="--K") from None


_INPUT = click.Path(exists=True, path_type=Path)


@main.command()
@click.option("--checkpoint", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Model weights (not needed with --method classical).")  # fmt: skip
@weights_option
@click.option("--rgb", type=_INPUT, default=None, help="PNG file or folder (with --sparse).")
@click.option("--sparse", type=_INPUT, default=None, help="16-bit PNG file or folder (with --rgb).")
@click.option(
    "--kitti-raw",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="A KITTI raw drive folder RAW_ROOT/DATE/DATE_drive_NNNN_sync (instead of --rgb/--sparse).",
)
@dataset_option("With --data: the dataset whose root --data is.")
@click.option("--data", "data_root", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="A dataset root (with --dataset; instead of --rgb/--sparse): the frames of --split.")  # fmt: skip
@click.option("--split", default=None, help="With --data: the split [the dataset's evaluation split].")
@click.option("--frames", default=None, help="With --kitti-raw: indices, a range a-b or a comma list (default all).")
@click.option("--camera", type=click.Choice(["2", "3"]), default="2", show_default=True, help="With --kitti-raw.")
@click.option("--semantic", type=_INPUT, default=None, help="PNG file or folder of colour-coded semantic maps.")
@click.option(
    "--segment",
    "segment_spec",
    default=None,
    metavar="SPEC",
    help="With --kitti-raw: segment each image with this model (see `semattnet segment --model`).",
)
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--npy", is_flag=True, help="Also write float32 .npy depth.")
@click.option("--panel", is_flag=True, help="Also write the per-branch panel (with --kitti-raw: a bird's-eye view).")
@click.option("--ply", is_flag=True, help="With --kitti-raw: also write the prediction as a binary PLY point cloud.")
@click.option(
    "--max-depth",
    type=POSITIVE_FLOAT,
    default=80.0,
    show_default=True,
    help="PLY / bird's-eye view: drop deeper pixels, m.",
)
@click.option(
    "--top-crop", type=COUNT, default=0, show_default=True, help="PLY / bird's-eye view: drop the top N rows (sky)."
)
@click.option("--deskew", is_flag=True, help="With --kitti-raw: ego-motion compensate scans with their OXTS data.")
@click.option("--device", default="auto", show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@backend_option
@click.option("--overwrite", is_flag=True, help="Replace existing outputs.")
@click.option("--method", type=click.Choice(["semattnet", "classical"]), default="semattnet", show_default=True,
              help="classical: the non-learned IP-Basic-style baseline (no checkpoint).")  # fmt: skip
@click.option("--report", is_flag=True, help="Also write viewer.html: hover depths, layers, 3D view (with --K).")
@click.option("--K", "intrinsics", default=None, metavar="fx,fy,cx,cy|kitti",
              help="With --report: camera intrinsics for the 3D view ('kitti': KITTI's camera 02).")  # fmt: skip
def predict(checkpoint: Path | None, weights: str | None, rgb: Path | None, sparse: Path | None,
            kitti_raw: Path | None, dataset: str, data_root: Path | None, split: str | None, frames: str | None,
            camera: str, semantic: Path | None, segment_spec: str | None,
            out: Path, npy: bool, panel: bool, ply: bool, max_depth: float, top_crop: int, deskew: bool, device: str,
            amp: str, backend: str, overwrite: bool, method: str, report: bool,
            intrinsics: str | None) -> None:  # fmt: skip
    """Complete depth for one frame, folders of frames (any size), a KITTI raw drive or a dataset's split."""
    from semattnet._utils.distributed import launch_rank, process_group
    from semattnet.data.sources import FolderSource, RawDriveSource, SemanticMaps
    from semattnet.inference.pipeline import check_frames, complete_frames
    from semattnet.inference.sinks import default_sinks

    if data_root is not None:
        if kitti_raw is not None or rgb is not None or sparse is not None or report or ply or frames or deskew:
            raise click.UsageError("--data takes none of --rgb, --sparse, --kitti-raw, --report, --ply, --frames")
    elif (kitti_raw is None) == (rgb is None and sparse is None) or (kitti_raw is None and None in (rgb, sparse)):
        raise click.UsageError("give --rgb and --sparse, or --kitti-raw (or --data with --dataset)")
    if kitti_raw is None and data_root is None and (ply or segment_spec or frames or deskew):
        raise click.UsageError("--ply, --segment, --frames and --deskew need --kitti-raw")
    if kitti_raw is not None and report:
        raise click.UsageError("--report needs --rgb/--sparse (not yet --kitti-raw)")
    _check_method(method, checkpoint, weights)
    K = _intrinsics(intrinsics)
    maps = SemanticMaps(segment_spec, folder=semantic is not None)
    sinks = default_sinks(npy, panel, ply, max_depth, top_crop)
    with process_group():
        if data_root is not None:
            from semattnet.data.datasets import get_dataset

            source = get_dataset(dataset).source(data_root, split, semantic_root=semantic)
        elif kitti_raw is not None:
            source = RawDriveSource(kitti_raw, frames, camera, semantic, deskew)
        else:
            source = FolderSource.pair(rgb, sparse, semantic, K=K)  # type: ignore[arg-type]
        check_frames(source, sinks, out, overwrite=overwrite)  # every input and output, before the model
        completer = _completer(method, checkpoint, weights, device, amp, backend)
        complete_frames(source, completer, sinks, out, overwrite=overwrite, log=click.echo, semantic=maps,
                        checked=True)  # fmt: skip
    if report and launch_rank() == 0:  # under torchrun: once, after every rank's frames are in place
        from semattnet.viz.viewer import write_prediction_report

        write_prediction_report(out, list(source.frames.values()), K=K, log=click.echo)  # type: ignore[attr-defined]


@main.command()
@click.option("--pred", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--gt", type=click.Path(exists=True, path_type=Path), default=None, help="Ground truth: adds error maps.")
@click.option(
    "--vmax", type=POSITIVE_FLOAT, default=80.0, show_default=True, help="Depth of the colour scale's top, metres."
)
@click.option("--overwrite", is_flag=True, help="Replace existing pictures.")
def visualize(pred: Path, out: Path, gt: Path | None, vmax: float, overwrite: bool) -> None:
    """Colourise saved depth predictions (and error maps against ground truth)."""
    from semattnet.viz.depth import write_depth_pictures

    count = write_depth_pictures(pred, out, gt, vmax, overwrite=overwrite)
    click.echo(f"wrote {count} picture(s) to {out}")
