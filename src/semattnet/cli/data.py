"""Commands about data: ``synth`` and ``data check``."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._group import main
from semattnet.cli._options import parse_size


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the KITTI-layout tree.",
)
@click.option("--frames", default=100, show_default=True, help="Training frames.")
@click.option(
    "--eval-frames", type=int, default=None, help="Frames for each of val, val_select, test [frames/5, >= 2]."
)
@click.option("--size", default="352x1216", show_default=True, help="Frame size HxW.")
@click.option("--seed", default=0, show_default=True)
@click.option("--workers", type=int, default=None, help="Processes [all cores]; the output does not depend on it.")
@click.option("--overwrite", is_flag=True, help="Write into a non-empty folder, replacing a previous tree.")
def synth(out_dir: Path, frames: int, eval_frames: int | None, size: str, seed: int, workers: int | None,
          overwrite: bool) -> None:  # fmt: skip
    """Generate synthetic KITTI-like scenes in the KITTI depth completion layout."""
    from semattnet.data.synthetic.tree import write_synthetic_kitti

    manifest = write_synthetic_kitti(out_dir, frames, parse_size(size), seed, eval_frames, workers, overwrite)
    counts = ", ".join(f"{k} {v}" for k, v in manifest["counts"].items())
    click.echo(f"wrote {out_dir}: {counts} (manifest: {out_dir / 'scenes.json'})")


@main.group()
def data() -> None:
    """Data sets: validation of KITTI / synthetic trees."""


@data.command("check")
@click.argument("roots", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--raw-root",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="KITTI raw data [ROOT/kitti_raw or ROOT/raw].",
)
@click.option(
    "--semantic-root",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Semantic maps [ROOT/semantic or ROOT/semantics].",
)
@click.option("--sample", type=int, default=None, help="Decode at most N frames per split [all].")
def data_check(roots: tuple[Path, ...], raw_root: Path | None, semantic_root: Path | None, sample: int | None) -> None:
    """Check KITTI depth completion trees; exits 1 if anything is missing, unpaired or broken."""
    from semattnet.data.check import check_trees

    if check_trees(roots, raw_root, semantic_root, sample, log=click.echo):
        raise SystemExit(1)
