"""``semattnet segment``: semantic maps from an off-the-shelf segmenter."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._group import main
from semattnet.cli._model import device_option
from semattnet.cli._options import BATCH_SIZE, SIZE, parse_size, parse_triple


@main.command()
@click.option(
    "--model",
    "spec",
    required=True,
    help="model.onnx, TorchScript file, torchvision:ARCH:WEIGHTS, hf:ORG/NAME | hf:PATH | hf:default "
    "(SegFormer-B5 Cityscapes) | hf:indoor (SegFormer-B5 ADE20K, maps in NYU-40; hf: needs "
    "semattnet[segment]), or 'unknown' (no segmenter).",
)
@click.option(
    "--images",
    required=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="Image tree, e.g. kitti_raw (searched recursively).",
)
@click.option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Semantic root; mirrors the image tree.",
)
@click.option("--batch-size", type=BATCH_SIZE, default=4, show_default=True)
@device_option(help="Where the segmenter runs: auto, cpu, cuda[:N] or mps.")
@click.option("--mean", default="0.485,0.456,0.406", show_default=True, help="Input normalisation (RGB in [0, 1]).")
@click.option("--std", default="0.229,0.224,0.225", show_default=True)
@click.option("--input-size", type=SIZE, default=None, help="Run the network at HxW (maps are resized back).")
@click.option(
    "--palette",
    type=click.Choice(["cityscapes", "nyu40"]),
    default=None,
    help="The maps' palette [hf:indoor: nyu40; else cityscapes]; an hf: model's classes are matched to it by name.",
)
@click.option("--overwrite", is_flag=True, help="Redo maps that already exist.")
def segment(
    spec: str,
    images: Path,
    out: Path,
    batch_size: int,
    device: str,
    mean: str,
    std: str,
    input_size: str | None,
    palette: str | None,
    overwrite: bool,
) -> None:
    """Write colour-coded semantic maps (Cityscapes or NYU-40) for every image; resumes where it stopped."""
    from semattnet.segmentation.segmenter import load_segmenter, segment_folder

    segmenter = load_segmenter(
        spec,
        device,
        parse_triple(mean, "--mean"),
        parse_triple(std, "--std"),
        parse_size(input_size) if input_size else None,
        palette,
    )
    done = segment_folder(segmenter, images, out, batch_size=batch_size, overwrite=overwrite)
    click.echo(f"wrote {done.written} maps to {out} ({done.skipped} already there, {done.total} images)")
