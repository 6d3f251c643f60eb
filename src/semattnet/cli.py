"""The ``semattnet`` command line: a thin layer over the library."""

from __future__ import annotations

import json
from pathlib import Path

import click

from . import __version__


def _size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected HxW, e.g. 96x320; got {text!r}") from None
    return h, w


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="semattnet")
def main() -> None:
    """SemAttNet depth completion: models, checkpoints and demos."""


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default="semattnet-demo",
    show_default=True,
    help="Folder for the pictures and metrics.",
)
@click.option("--size", default="96x320", show_default=True, help="Scene size HxW (multiples of 32).")
@click.option("--width", default=0.125, show_default=True, help="Model width multiplier (1.0 = paper).")
@click.option("--steps", default=60, show_default=True, help="Training steps.")
@click.option("--seed", default=0, show_default=True)
@click.option("--device", default="auto", show_default=True, help="auto, cpu or cuda[:N].")
def demo(out_dir: Path, size: str, width: float, steps: int, seed: int, device: str) -> None:
    """Train a small SemAttNet on generated scenes and complete a held-out frame (no download)."""
    from .demo import run_demo

    run_demo(out_dir, size=_size(size), width=width, steps=steps, seed=seed, device=device, log=click.echo)


@main.command()
@click.option("--params/--no-params", default=False, help="Also build each model to count its parameters.")
def models(params: bool) -> None:
    """List the registered models (paper model and Table 2 ablations)."""
    from .registry import MODELS, build_model

    for name, (description, _) in MODELS.items():
        count = f"{sum(p.numel() for p in build_model(name).parameters()):>13,d}  " if params else ""
        click.echo(f"{name:20s} {count}{description}")


@main.command()
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def info(checkpoint: Path) -> None:
    """Show what a checkpoint holds (never runs code from it)."""
    from .checkpoint import config_from_state_dict, load_checkpoint

    ckpt = _load_or_exit(checkpoint, load_checkpoint)
    cfg = ckpt.config or config_from_state_dict(ckpt.state_dict)
    n = sum(v.numel() for k, v in ckpt.state_dict.items() if not k.endswith("num_batches_tracked"))
    click.echo(f"file:        {ckpt.path}  ({ckpt.format})")
    click.echo(f"entries:     {len(ckpt.state_dict)} tensors, {n:,d} values")
    click.echo(f"model:       {json.dumps(cfg.to_dict())}")
    if ckpt.epoch is not None:
        click.echo(f"epoch:       {ckpt.epoch}")
    if ckpt.best_result is not None:
        click.echo(f"best_result: {ckpt.best_result!r}")
    if ckpt.neutralised:
        click.echo(f"neutralised: {', '.join(sorted(ckpt.neutralised))} (loaded as inert records)")


@main.command()
@click.argument("src", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("dst", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--overwrite", is_flag=True, help="Replace DST if it exists.")
def convert(src: Path, dst: Path, overwrite: bool) -> None:
    """Convert a checkpoint (authors' .pth.tar, state dict) to weights-only safetensors."""
    from .checkpoint import load_checkpoint, save_safetensors

    if dst.exists() and not overwrite:
        raise click.ClickException(f"{dst} exists; pass --overwrite to replace it")
    ckpt = _load_or_exit(src, load_checkpoint)
    save_safetensors(ckpt, dst)
    click.echo(f"wrote {dst} ({len(ckpt.state_dict)} tensors, {dst.stat().st_size / 2**20:.1f} MiB)")


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
    from .data.synthetic_tree import write_synthetic_kitti

    try:
        manifest = write_synthetic_kitti(out_dir, frames, _size(size), seed, eval_frames, workers, overwrite)
    except FileExistsError as exc:
        raise click.ClickException(str(exc)) from None
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
    from .data.check import check_tree

    bad = 0
    for root in roots:
        reports = check_tree(root, raw_root, semantic_root, sample)
        click.echo(f"{root}:")
        if not reports:
            click.echo("  no KITTI depth completion files found")
            bad += 1
        for rep in reports:
            click.echo("  " + rep.summary())
            for problem in rep.problems[:20]:
                click.echo(f"    - {problem}")
            if len(rep.problems) > 20:
                click.echo(f"    ... {len(rep.problems) - 20} more")
            bad += len(rep.problems)
    if bad:
        raise SystemExit(1)


def _load_or_exit(path: Path, loader):  # type: ignore[no-untyped-def]
    """Run ``loader(path)``; a bad or unsafe checkpoint becomes a one-line CLI error."""
    from .checkpoint import CheckpointError, UnsafeCheckpointError

    try:
        return loader(path)
    except (CheckpointError, UnsafeCheckpointError) as exc:
        raise click.ClickException(str(exc)) from None


if __name__ == "__main__":
    main()
