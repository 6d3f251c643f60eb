"""Option parsing shared by the commands: sizes, triples, comma lists."""

from __future__ import annotations

from pathlib import Path

import click
import torch


def parse_size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected HxW, e.g. 96x320; got {text!r}") from None
    return h, w


def parse_triple(text: str, option: str) -> tuple[float, float, float]:
    try:
        a, b, c = (float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(f"expected three numbers R,G,B; got {text!r}", param_hint=option) from None
    return a, b, c


#: ``--weights NAME|PATH|URL``: every command that reads a model takes it beside ``--checkpoint``.
weights_option = click.option(
    "--weights",
    default=None,
    metavar="NAME|PATH|URL",
    help="Released weights by name (semattnet weights list), a local file or folder, an http(s)/file URL or hf://owner/repo.",
)


def model_from_options(checkpoint: Path | None, weights: str | None, device: str = "cpu") -> torch.nn.Module:
    """The model named by ``--checkpoint`` or ``--weights`` (exactly one of them)."""
    from semattnet.weights import from_pretrained, load_model

    if checkpoint is not None and weights is not None:
        raise click.UsageError("give --checkpoint or --weights, not both")
    if weights is not None:
        return from_pretrained(weights, map_location=device)
    if checkpoint is not None:
        return load_model(checkpoint, device=device)
    raise click.UsageError("--checkpoint or --weights is required")
