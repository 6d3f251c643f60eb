"""Commands about data: ``synth``, ``data check`` and ``data download``."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._dataset import dataset_option
from semattnet.cli._group import main
from semattnet.cli._options import COUNT, MAX_COUNT, POSITIVE_INT, SIZE, parse_size
from semattnet.synthetic.scenes import SCENE_STYLES


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the KITTI-layout tree.",
)
@click.option("--frames", type=POSITIVE_INT, default=100, show_default=True, help="Training frames.")
@click.option(
    "--eval-frames",
    type=click.IntRange(min=2, max=MAX_COUNT),
    default=None,
    help="Frames for each of val, val_select, test [frames/5, >= 2].",
)
@click.option("--size", type=SIZE, default="352x1216", show_default=True, help="Frame size HxW.")
@click.option("--seed", type=COUNT, default=0, show_default=True)
@click.option(
    "--workers",
    type=click.IntRange(min=1, max=256),
    default=None,
    help="Processes [all cores]; the output does not depend on it.",
)
@click.option("--overwrite", is_flag=True, help="Write into a non-empty folder, replacing a previous tree.")
@click.option(
    "--style",
    type=click.Choice(SCENE_STYLES),
    default=SCENE_STYLES[0],
    show_default=True,
    help="ideal: LiDAR on every surface; realistic: LiDAR fails on dark/glossy paint and glass, far and grazing "
    "surfaces, road markings and posters, grey cars before grey walls (semantics carry information).",
)
def synth(
    out_dir: Path,
    frames: int,
    eval_frames: int | None,
    size: str,
    seed: int,
    workers: int | None,
    overwrite: bool,
    style: str,
) -> None:
    """Generate synthetic KITTI-like scenes in the KITTI depth completion layout."""
    from semattnet.synthetic.tree import write_synthetic_kitti

    manifest = write_synthetic_kitti(
        out_dir, frames, parse_size(size), seed, eval_frames, workers, overwrite, style=style
    )
    counts = ", ".join(f"{k} {v}" for k, v in manifest["counts"].items())
    click.echo(f"wrote {out_dir}: {counts} (manifest: {out_dir / 'scenes.json'})")


@main.group()
def data() -> None:
    """Data sets: download and validation of KITTI / synthetic trees."""


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
@click.option("--sample", type=POSITIVE_INT, default=None, help="Decode at most N frames per split [all].")
@dataset_option("The layout to check.")
def data_check(
    roots: tuple[Path, ...], raw_root: Path | None, semantic_root: Path | None, sample: int | None, dataset: str
) -> None:
    """Check dataset trees (KITTI depth completion by default); exits 1 if anything is missing, unpaired or broken."""
    from semattnet.data.datasets import get_dataset

    if get_dataset(dataset).check(roots, raw_root, semantic_root, sample, log=click.echo):
        raise SystemExit(1)


@data.command("download")
@click.option(
    "--what",
    default="depth-completion,raw-subset",
    show_default=True,
    help="Comma list of depth-completion, raw-subset, semantic (or all).",
)
@click.option(
    "--out",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Root of the KITTI tree (data_depth_*, kitti_raw, semantic).",
)
@click.option("--accept-kitti-license", is_flag=True, help="Accept KITTI's CC BY-NC-SA 3.0 terms (required).")
@click.option("--dry-run", is_flag=True, help="Print every URL, size and target folder; download nothing.")
@click.option(
    "--mirror",
    default=None,
    metavar="URL_PREFIX",
    help="Fetch from this prefix instead of KITTI's server (same paths below it).",
)
@click.option(
    "--semantic-archive",
    default=None,
    metavar="PATH|URL",
    help="The authors' semantic maps (a zip you downloaded), unpacked into OUT/semantic.",
)
@click.option(
    "--cache-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Download cache [$SEMATTNET_CACHE or the user cache].",
)
@click.option("--delete-archives", is_flag=True, help="Delete each downloaded archive once it is unpacked.")
@click.option("--check/--no-check", default=True, show_default=True, help="Run `data check` on OUT at the end.")
@dataset_option("What to download (nyuv2, void: their archives into OUT; --what is KITTI's).")
@click.option("--accept-license", is_flag=True, help="Accept the dataset's terms (nyuv2, void; printed first).")
def data_download(
    what: str,
    out_dir: Path,
    accept_kitti_license: bool,
    dry_run: bool,
    mirror: str | None,
    semantic_archive: str | None,
    cache_dir: Path | None,
    delete_archives: bool,
    check: bool,
    dataset: str,
    accept_license: bool,
) -> None:
    """Download a dataset (KITTI depth completion and the raw drives it needs by default) into the loader
    layout; exits 1 on problems."""
    from semattnet.cache import DownloadError
    from semattnet.data.download import download_dataset
    from semattnet.data.kitti.download import download_kitti

    try:
        if dataset != "kitti-dc":
            problems = download_dataset(
                dataset,
                out_dir,
                accept_license=accept_license,
                dry_run=dry_run,
                mirror=mirror,
                cache_dir=cache_dir,
                delete_archives=delete_archives,
                check=check,
                log=click.echo,
            )
            if problems:
                raise SystemExit(1)
            return
        problems = download_kitti(
            out_dir,
            what,
            accept_license=accept_kitti_license,
            dry_run=dry_run,
            mirror=mirror,
            semantic_archive=semantic_archive,
            cache_dir=cache_dir,
            delete_archives=delete_archives,
            check=check,
            log=click.echo,
        )
    except DownloadError as exc:
        raise click.ClickException(f"{exc} (run the same command again to resume)") from None
    if problems:
        raise SystemExit(1)
