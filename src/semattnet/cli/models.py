"""Commands about models and weights: ``models``, ``info``, ``convert``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from semattnet.cli._group import main


@main.command()
@click.option("--params/--no-params", default=False, help="Also build each model to count its parameters.")
def models(params: bool) -> None:
    """List the registered models (paper model and Table 2 ablations)."""
    from semattnet.models.registry import describe_models

    click.echo(describe_models(count_parameters=params))


@main.command()
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def info(checkpoint: Path) -> None:
    """Show what a checkpoint holds (never runs code from it)."""
    from semattnet.weights.checkpoint import config_from_state_dict, load_checkpoint

    ckpt = load_checkpoint(checkpoint)
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
    from semattnet.weights.checkpoint import load_checkpoint, save_safetensors

    if dst.exists() and not overwrite:
        raise click.ClickException(f"{dst} exists; pass --overwrite to replace it")
    ckpt = load_checkpoint(src)
    save_safetensors(ckpt, dst)
    click.echo(f"wrote {dst} ({len(ckpt.state_dict)} tensors, {dst.stat().st_size / 2**20:.1f} MiB)")
