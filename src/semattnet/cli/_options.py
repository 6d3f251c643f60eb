"""Option parsing and validation shared by every command: ranges, finite numbers, sizes, triples.

Every numeric option of every command uses one of these types, so a bad value is refused with
a one-line error naming the option before any work starts.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import click
import torch

from semattnet._utils.bounds import MAX_SKEW_S
from semattnet.cli._params import section

if TYPE_CHECKING:
    from semattnet.weights.resolve import ResolvedWeights

#: The heading of the options choosing and running the model, in a sectioned ``--help``.
MODEL = "Model"

#: Largest count any option takes (frames, steps, epochs, repeats): far above any real run, and below
#: the sizes where a count would overflow an int64 or be allocated as a list.
MAX_COUNT = 1_000_000_000
#: A count of at least one (frames, steps, repeats), at most :data:`MAX_COUNT`.
POSITIVE_INT = click.IntRange(min=1, max=MAX_COUNT)
#: A count that may be zero (0 = "none" / "all", as each option's help says), at most :data:`MAX_COUNT`.
COUNT = click.IntRange(min=0, max=MAX_COUNT)
#: A batch size: every item of a batch is allocated at once.
BATCH_SIZE = click.IntRange(min=1, max=4096)
#: Data loading processes (0: in the main process).
WORKERS = click.IntRange(min=0, max=256)
#: Largest side accepted by size options (the same limit :mod:`semattnet.data.io` reads).
MAX_SIDE = 16384
#: Rows or columns of an image (``--top-crop``).
PIXELS = click.IntRange(min=0, max=MAX_SIDE)


class FiniteFloat(click.ParamType):
    """A float that is not NaN or infinite, optionally within ``[low, high]`` (``low_open``: > low)."""

    name = "float"

    def __init__(self, low: float | None = None, high: float | None = None, low_open: bool = False) -> None:
        self.low, self.high, self.low_open = low, high, low_open

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> float:
        try:
            x = float(value if isinstance(value, int | float) else str(value))
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(x):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        if self.low is not None and (x <= self.low if self.low_open else x < self.low):
            self.fail(f"{value!r} must be {'>' if self.low_open else '>='} {self.low:g}", param, ctx)
        if self.high is not None and x > self.high:
            self.fail(f"{value!r} must be <= {self.high:g}", param, ctx)
        return x


#: Largest float any option takes unless its own type says less: finite, and far from the float range's
#: end (``1e300`` seconds times 1e9 nanoseconds is infinite).
MAX_FLOAT = 1e9
#: A strictly positive finite float, at most :data:`MAX_FLOAT`.
POSITIVE_FLOAT = FiniteFloat(0.0, MAX_FLOAT, low_open=True)
#: A finite float in [0, :data:`MAX_FLOAT`].
NONNEGATIVE_FLOAT = FiniteFloat(0.0, MAX_FLOAT)
#: A depth in metres: the largest depth a model accepts (``semattnet.models.checks.MAX_INPUT_DEPTH_M``).
DEPTH_M = FiniteFloat(0.0, 1000.0, low_open=True)
#: A depth threshold in metres that may be 0.
DEPTH_M_OR_ZERO = FiniteFloat(0.0, 1000.0)
#: Seconds between two stamps: at most ``semattnet._utils.bounds.MAX_SKEW_S`` (an hour).
SECONDS = FiniteFloat(0.0, MAX_SKEW_S)
#: A sensor's period in seconds: > 0, at most an hour.
PERIOD = FiniteFloat(0.0, 3600.0, low_open=True)
#: A replay speed factor: at most 100 times slower (a wait between frames is capped besides) or 1000 times faster.
SPEED = FiniteFloat(0.01, 1000.0)
#: A learning rate.
LEARNING_RATE = FiniteFloat(0.0, 10.0, low_open=True)
#: A model width multiplier: ``semattnet.models.config.RANGES["width"]``.
WIDTH = FiniteFloat(0.125, 4.0)


def require_with(needs: str, present: bool, *names: str) -> None:
    """Refuse options the user gave (not defaults) that only mean something with ``needs`` when it is absent:
    an option that would be silently ignored is a usage error (exit 2) naming both."""
    ctx = click.get_current_context()
    given = [n for n in names if ctx.get_parameter_source(n) not in (None, click.core.ParameterSource.DEFAULT)]
    if given and not present:
        flags = {p.name: p.opts[0] for p in ctx.command.params}
        shown = ", ".join(flags.get(n, n) for n in given)
        raise click.UsageError(f"{shown} only mean(s) something with {needs}; {needs} is not given")


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

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> str:
        try:
            parse_size(str(value))
        except click.BadParameter as exc:
            self.fail(exc.message, param, ctx)
        return str(value)


SIZE = SizeType()


class SeedsType(click.ParamType):
    """Comma-separated non-negative integers, e.g. ``0,1,2`` -> (0, 1, 2), no repeats."""

    name = "SEEDS"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> tuple[int, ...]:
        if isinstance(value, tuple):  # a default, already converted
            return tuple(int(str(v)) for v in value)
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


WEIGHTS_HELP = (
    "Model weights: a released name (semattnet weights list), a local file (.pth.tar, .pt, .safetensors) or "
    "folder (save_pretrained), an http(s)/file URL, gdrive://ID or hf://owner/repo. "
    "--checkpoint is an alias of this option (its older name)."
)


class WeightsSpecType(click.ParamType):
    """``NAME|PATH|URL``: checked by :func:`semattnet.weights.parse_weights_spec` (the one parser), not fetched."""

    name = "NAME|PATH|URL"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> str:
        from semattnet.weights.resolve import ShadowedNameWarning, WeightsSpecError, parse_weights_spec

        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ShadowedNameWarning)
                parse_weights_spec(str(value))
        except WeightsSpecError as exc:
            self.fail(str(exc), param, ctx)
        for note in caught:  # a name that a local file or folder shadows: said once, in one line
            if not issubclass(note.category, ShadowedNameWarning):
                warnings.warn(note.message, note.category, stacklevel=2)
                continue
            click.echo(f"note: {note.message}", err=True)
            warnings.filterwarnings("ignore", category=ShadowedNameWarning)  # not again when it is resolved
        return str(value)


WEIGHTS_SPEC = WeightsSpecType()

_Callback = Callable[[click.Context, click.Parameter, tuple[str, ...]], str | None]
_F = TypeVar("_F", bound=Callable[..., object])


def one_value(spec: click.ParamType) -> _Callback:
    """The callback of an option with aliases, declared ``multiple`` (of plain text) only to see a second
    use (``--checkpoint A --weights B``): refuse that first, then check the one value with ``spec``."""

    def callback(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]) -> str | None:
        if len(values) > 1:
            primary, *aliases = param.opts
            names = " or ".join([*aliases, primary])
            raise click.BadParameter(
                f"{', '.join(aliases) or primary} is an alias of {primary}: give exactly one of {names}, not both",
                ctx=ctx,
                param=param,
            )
        return str(spec.convert(values[0], param, ctx)) if values else None

    return callback


def weights_option(f: _F) -> _F:
    """``--weights NAME|PATH|URL`` with ``--checkpoint`` as its alias: the one loader option of every command
    that reads a model. The command receives it as ``weights`` (a str, or None)."""
    option = click.option(
        "--weights",
        "--checkpoint",
        "weights",
        cls=section(MODEL),
        multiple=True,
        callback=one_value(WEIGHTS_SPEC),
        metavar="NAME|PATH|URL",
        help=WEIGHTS_HELP,
    )
    return option(f)


def weights_input(weights: str | None) -> tuple[str, Path | None]:
    """``--weights`` as an input of the output rule (``semattnet._utils.outputs.check_outputs``): its path when
    it names a local file or folder (a name or URL reads a cached download, which no option can name)."""
    return "--weights", Path(weights) if weights is not None and Path(weights).exists() else None


def resolve_option(spec: str, param_hint: str = "--weights", progress: bool = True) -> ResolvedWeights:
    """:func:`semattnet.weights.resolve_weights` with a spec that names nothing reported as a usage error of
    ``param_hint`` (a corrupt or refused file is another SemAttNetError: a one-line error, not a usage error)."""
    from semattnet.weights.resolve import WeightsSpecError, resolve_weights

    try:
        return resolve_weights(spec, progress=progress)
    except WeightsSpecError as exc:
        raise click.BadParameter(str(exc), param_hint=param_hint) from None


def model_from_options(weights: str | None, device: str = "cpu") -> torch.nn.Module:
    """The model of ``--weights`` (``--checkpoint``), through :func:`semattnet.weights.from_pretrained`."""
    from semattnet.weights.hub import from_pretrained

    if weights is None:
        raise click.UsageError("--checkpoint or --weights is required (they are one option: --checkpoint is an alias)")
    return from_pretrained(weights, map_location=device)


def check_calibration_frames(calibration: Path) -> None:
    """``--calibration``'s frames read and checked before any work: a file, an empty folder, a corrupt PNG or a
    frame without a LiDAR point is one line naming the option and the file, never blamed on the frames."""
    from semattnet.inference.backends.calibration import CalibrationError, calibration_frames

    try:
        calibration_frames(calibration)
    except CalibrationError as exc:
        raise click.BadParameter(str(exc).removeprefix("calibration: "), param_hint="'--calibration'") from None
