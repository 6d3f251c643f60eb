"""Option parsing and validation shared by every command: ranges, finite numbers, sizes, triples.

Every numeric option of every command uses one of these types, so a bad value is refused with
a one-line error naming the option before any work starts.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import click
import torch

from semattnet._errors import SemAttNetError

#: A count of at least one (frames, steps, repeats, batch size).
POSITIVE_INT = click.IntRange(min=1)
#: A count that may be zero (0 = "none" / "all", as each option's help says).
COUNT = click.IntRange(min=0)
#: Largest side accepted by size options (the same limit :mod:`semattnet.data.io` reads).
MAX_SIDE = 16384


class FiniteFloat(click.ParamType):
    """A float that is not NaN or infinite, optionally within ``[low, high]`` (``low_open``: > low)."""

    name = "float"

    def __init__(self, low: float | None = None, high: float | None = None, low_open: bool = False) -> None:
        self.low, self.high, self.low_open = low, high, low_open

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> float:
        try:
            x = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(x):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        if self.low is not None and (x <= self.low if self.low_open else x < self.low):
            self.fail(f"{value!r} must be {'>' if self.low_open else '>='} {self.low:g}", param, ctx)
        if self.high is not None and x > self.high:
            self.fail(f"{value!r} must be <= {self.high:g}", param, ctx)
        return x


#: A strictly positive finite float (learning rates, widths, depths in metres, minutes).
POSITIVE_FLOAT = FiniteFloat(0.0, low_open=True)
#: A finite float >= 0.
NONNEGATIVE_FLOAT = FiniteFloat(0.0)


def parse_size(text: str, option: str | None = None, order: str = "HxW") -> tuple[int, int]:
    """``"96x320"`` -> ``(96, 320)``; both sides must be whole numbers in 1..MAX_SIDE."""
    try:
        a, b = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected {order}, e.g. 96x320; got {text!r}", param_hint=option) from None
    if not (0 < a <= MAX_SIDE and 0 < b <= MAX_SIDE):
        raise click.BadParameter(f"{order} sides must be in 1..{MAX_SIDE}; got {text!r}", param_hint=option)
    return a, b


class SizeType(click.ParamType):
    """``HxW`` with both sides > 0 (returned as the text, validated: commands parse it with :func:`parse_size`)."""

    name = "HxW"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        try:
            parse_size(value)
        except click.BadParameter as exc:
            self.fail(exc.message, param, ctx)
        return str(value)


SIZE = SizeType()


class SeedsType(click.ParamType):
    """Comma-separated non-negative integers, e.g. ``0,1,2`` -> (0, 1, 2), no repeats."""

    name = "SEEDS"

    def convert(self, value, param, ctx):  # type: ignore[no-untyped-def]
        if isinstance(value, tuple):
            return value
        try:
            seeds = tuple(int(v) for v in str(value).split(","))
        except ValueError:
            self.fail(f"expected comma-separated integers, got {value!r}", param, ctx)
        if any(v < 0 for v in seeds) or len(set(seeds)) != len(seeds):
            self.fail(f"expected distinct non-negative integers, got {value!r}", param, ctx)
        return seeds


SEEDS = SeedsType()


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


#: ``--backend``: the inference engine of every command that runs a model (see ``optimize_for_inference``).
backend_option = click.option(
    "--backend",
    type=click.Choice(["torch", "openvino", "onnxruntime", "auto"]),
    default="torch",
    show_default=True,
    help="Inference engine: torch (BN folded, fused propagation), openvino / onnxruntime (exported once per "
    "frame size, cached on disk; worth it over many frames) or auto.",
)


def weights_path(spec: str, param_hint: str = "--weights", progress: bool = True) -> Path:
    """``resolve_weights_file`` with a bad name or path reported as a usage error of ``param_hint``."""
    from semattnet.weights.listing import resolve_weights_file

    try:
        return resolve_weights_file(spec, progress=progress)
    except ValueError as exc:
        if isinstance(exc, SemAttNetError):  # a corrupt or refused file: a one-line error, not a usage error
            raise
        raise click.BadParameter(str(exc).removeprefix(f"--weights {spec!r}: "), param_hint=param_hint) from None
