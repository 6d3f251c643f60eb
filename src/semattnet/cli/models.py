"""Commands about models and weights: ``models``, ``info``, ``convert``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from semattnet.cli._group import main
from semattnet.cli._options import weights_option


def _source(checkpoint: Path | None, weights: str | None) -> Path:
    """The local file named by CHECKPOINT or ``--weights`` (exactly one of them)."""
    from semattnet.cli._options import weights_path

    if (checkpoint is None) == (weights is None):
        raise click.UsageError("give a CHECKPOINT file or --weights NAME|PATH|URL (one of them)")
    return checkpoint if checkpoint is not None else weights_path(weights)  # type: ignore[arg-type]


@main.command()
@click.option("--params/--no-params", default=False, help="Also build each model to count its parameters.")
def models(params: bool) -> None:
    """List the registered models (paper model and Table 2 ablations)."""
    from semattnet.models.registry import describe_models

    click.echo(describe_models(count_parameters=params))


@main.command()
@click.argument("checkpoint", required=False, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@weights_option
def info(checkpoint: Path | None, weights: str | None) -> None:
    """Show what a checkpoint (or --weights) holds (never runs code from it)."""
    from semattnet.weights.checkpoint import config_from_state_dict, load_checkpoint

    ckpt = load_checkpoint(_source(checkpoint, weights))
    cfg = ckpt.config or config_from_state_dict(ckpt.state_dict, ckpt.path)
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
@click.argument("paths", nargs=-1, required=True, metavar="[SRC] DST", type=click.Path(dir_okay=False, path_type=Path))
@weights_option
@click.option("--overwrite", is_flag=True, help="Replace DST if it exists.")
def convert(paths: tuple[Path, ...], weights: str | None, overwrite: bool) -> None:
    """Convert a checkpoint SRC (or --weights) to weights-only safetensors DST."""
    from semattnet.weights.checkpoint import load_checkpoint, save_safetensors

    if len(paths) != (1 if weights is not None else 2):
        raise click.UsageError("expected SRC DST, or --weights NAME|PATH|URL DST")
    src, dst = (None, paths[0]) if weights is not None else paths
    if src is not None and not src.is_file():
        raise click.BadParameter(f"{src}: no such file", param_hint="SRC")
    from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs

    source = _source(src, weights)  # --weights NAME|URL resolves to a (cached) file too
    check_no_input_overlap([source], out_files=[dst])
    check_outputs([("SRC" if src is not None else "--weights", source)], [Output("DST", dst, "safetensors")],
                  overwrite)  # fmt: skip
    ckpt = load_checkpoint(source)
    save_safetensors(ckpt, dst)
    click.echo(f"wrote {dst} ({len(ckpt.state_dict)} tensors, {dst.stat().st_size / 2**20:.1f} MiB)")
