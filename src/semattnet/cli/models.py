"""Commands about models and weights: ``models``, ``info``, ``convert``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import click

from semattnet.cli._group import main
from semattnet.cli._options import WEIGHTS_SPEC, weights_option

if TYPE_CHECKING:
    from semattnet.weights.resolve import ResolvedWeights


def _one_spec(given: str | None, weights: str | None, what: str) -> ResolvedWeights:
    """The weights named by the positional ``what`` or ``--weights`` (exactly one of them), resolved."""
    from semattnet.cli._options import resolve_option

    if (given is None) == (weights is None):
        raise click.UsageError(f"give a {what} or --weights NAME|PATH|URL (one of them)")
    return resolve_option(given, what) if given is not None else resolve_option(str(weights))


@main.command()
@click.option("--params/--no-params", default=False, help="Also build each model to count its parameters.")
def models(params: bool) -> None:
    """List the registered models (paper model and Table 2 ablations)."""
    from semattnet.models.registry import describe_models

    click.echo(describe_models(count_parameters=params))


@main.command()
@click.argument("source", required=False, metavar="[NAME|PATH|URL]", type=WEIGHTS_SPEC)
@weights_option
def info(source: str | None, weights: str | None) -> None:
    """Show what weights hold: a file, a save_pretrained folder, a registered name or a URL (never runs code)."""
    from semattnet.weights.checkpoint import config_from_state_dict, load_checkpoint

    resolved = _one_spec(source, weights, "NAME|PATH|URL")
    ckpt = load_checkpoint(resolved.file)  # the file as it is (a downloaded pickle, not its converted copy)
    cfg = resolved.config or ckpt.config or config_from_state_dict(ckpt.state_dict, ckpt.path)
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

    source = _one_spec(str(src) if src is not None else None, weights, "SRC").file  # NAME|URL: a cached file
    check_no_input_overlap([source], out_files=[dst])
    check_outputs([("SRC" if src is not None else "--weights", source)], [Output("DST", dst, "safetensors")], overwrite)
    ckpt = load_checkpoint(source)
    save_safetensors(ckpt, dst)
    click.echo(f"wrote {dst} ({len(ckpt.state_dict)} tensors, {dst.stat().st_size / 2**20:.1f} MiB)")
