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


def _load_or_exit(path: Path, loader):  # type: ignore[no-untyped-def]
    """Run ``loader(path)``; a bad or unsafe checkpoint becomes a one-line CLI error."""
    from .checkpoint import CheckpointError, UnsafeCheckpointError

    try:
        return loader(path)
    except (CheckpointError, UnsafeCheckpointError) as exc:
        raise click.ClickException(str(exc)) from None


if __name__ == "__main__":
    main()
