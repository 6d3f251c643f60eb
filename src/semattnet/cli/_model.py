"""The "Model" option section, declared once: which model runs, on which engine, in which arithmetic, where.

:func:`model_options` gives a command the whole section in one line (``--weights``, ``--method``, ``--device``,
``--backend``, ``--precision``, ``--calibration`` and ``--amp``, the older name of ``--precision``);
:class:`ModelOptions` is its parsed values: :meth:`~ModelOptions.check` refuses options that disagree (before any
work), :attr:`~ModelOptions.spec` is the one :class:`~semattnet.inference.backends.EngineSpec` and
:meth:`~ModelOptions.completer` the one completer (:func:`semattnet.inference.completer.load_completer`).
``--backend`` and ``--precision`` list what the engine table holds
(:mod:`semattnet.inference.backends.registry`), so a registered engine is a choice with no edit here.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import click

from semattnet._errors import SemAttNetError
from semattnet.cli._options import MODEL, check_calibration_frames, require_with, weights_option
from semattnet.cli._params import section

if TYPE_CHECKING:
    from semattnet.inference.backends import EngineSpec
    from semattnet.inference.contract import Completer

__all__ = ["ModelOptions", "device_option", "model_options", "palette_mismatch_option", "precision_options"]

_F = TypeVar("_F", bound=Callable[..., object])
_MODEL = section(MODEL)


class RegistryChoice(click.Choice):
    """A ``click.Choice`` whose choices are read from the engine table when first needed (not at import)."""

    def __init__(self, read: Callable[[], Sequence[str]]) -> None:
        self._read = read
        super().__init__([])

    @property  # type: ignore[override]
    def choices(self) -> Sequence[str]:
        return tuple(self._read())

    @choices.setter
    def choices(self, value: Sequence[str]) -> None:  # click.Choice.__init__ sets it: the table decides
        pass


def _backends() -> list[str]:
    from semattnet.inference.backends import engine_entries

    return [*engine_entries(), "auto"]


def _precisions() -> tuple[str, ...]:
    from semattnet.inference.backends import precisions

    return precisions()


def device_option(
    default: str | None = "auto",
    help: str = "Where the network runs: auto, cpu, cuda[:N] or mps.",
    cls: type[click.Option] = click.Option,
) -> Callable[[_F], _F]:
    """``--device``, the one declaration of every command's device option."""
    return click.option("--device", cls=cls, default=default, show_default=default is not None, help=help)


def palette_mismatch_option(cls: type[click.Option] = click.Option) -> click.Option:
    """``--palette-mismatch``: what to do with semantic maps of another palette than the model's."""
    return cls(
        ["--palette-mismatch"],
        type=click.Choice(["refuse", "recolour", "fallback"]),
        default="refuse",
        show_default=True,
        help="Maps of another palette than the model's (a KITTI model on nyuv2): refuse, "
        "recolour the classes both palettes name (the rest unknown), or use the fallback map (evaluate: "
        "metrics.json's 'semantic' says which).",
    )


def precision_options(f: _F, backend: bool = True) -> _F:
    """``--precision`` (the engine table's) and ``--calibration PATH`` (int8 only); ``backend``: whether the command
    has ``--backend`` (without it, the arithmetic of every backend it runs)."""
    f = click.option(
        "--calibration",
        cls=_MODEL,
        type=click.Path(exists=True, path_type=Path),
        default=None,
        help="With --precision int8: the frames NNCF measures value ranges on: a folder with rgb/ + sparse/ "
        "(+ semantic/), or a KITTI / synth root (its val_select) [8 synthetic street scenes].",
    )(f)
    return click.option(
        "--precision",
        cls=_MODEL,
        type=RegistryChoice(_precisions),
        default=None,
        help=(
            "The network's arithmetic, as --backend runs it: "
            if backend
            else "The network's arithmetic, for each backend that runs it: "
        )
        + "f32 [default], bf16 (faster only on CPUs with native bfloat16), fp16 (CUDA), int8 (OpenVINO + NNCF"
        + (": --backend openvino" if backend else "")
        + "; quantised once per weights, size and calibration, then cached).",
    )(f)


def model_options(method: bool = True) -> Callable[[_F], _F]:
    """The Model section (``method``: with ``--method semattnet|classical|prior`` and ``--prior``) in one line:
    ``@model_options()``.
    The command receives the fields of :class:`ModelOptions` (``values_of(ModelOptions, params)``)."""

    def decorate(f: _F) -> _F:
        f = click.option(
            "--amp",
            cls=_MODEL,
            type=click.Choice(["none", "bf16", "fp16"]),
            default=None,
            help="Deprecated: the older name of --precision (none = f32).",
        )(f)
        f = precision_options(f)
        f = click.option(
            "--backend",
            cls=_MODEL,
            type=RegistryChoice(_backends),
            default="torch",
            show_default=True,
            help="Inference engine: torch (BN folded, fused propagation), openvino / onnxruntime "
            "(exported once per frame size, cached on disk; worth it over many frames), tensorrt "
            "(CUDA) or auto.",
        )(f)
        f = device_option(cls=_MODEL)(f)
        if method:
            f = click.option(
                "--prior",
                cls=_MODEL,
                metavar="hf:ORG/NAME|hf:PATH",
                default=None,
                help="--method prior's monocular depth model (transformers' AutoModelForDepthEstimation, e.g. "
                "hf:depth-anything/Depth-Anything-V2-Small-hf), fitted to each frame's sparse points.",
            )(f)
            f = click.option(
                "--method",
                cls=_MODEL,
                type=click.Choice(["semattnet", "classical", "prior"]),
                default="semattnet",
                show_default=True,
                help="classical: the non-learned IP-Basic-style baseline (no weights); prior: a monocular depth "
                "model (--prior) put on the sparse points' scale (no weights).",
            )(f)
        return weights_option(f)

    return decorate


def check_calibration(precision: str | None) -> None:
    """``--calibration`` only with ``--precision int8`` (a usage error naming both)."""
    require_with("--precision int8", precision == "int8", "calibration")


@dataclass(frozen=True)
class ModelOptions:
    """The Model section's values: which completer, on which device, in which arithmetic and engine."""

    weights: str | None
    method: str
    device: str
    amp: str | None
    backend: str
    precision: str | None
    calibration: Path | None
    prior: str | None = None

    def check(self) -> None:
        """The options agree (usage errors, before any work): no option that would be ignored, weights when the
        method needs them, an engine that runs the precision on the device."""
        require_with("--method prior", self.method == "prior", "prior")
        if self.method in ("classical", "prior"):
            if self.weights is not None:
                raise click.UsageError(f"--method {self.method} uses no model: drop --checkpoint / --weights")
            if self.method == "prior" and self.prior is None:
                raise click.UsageError("--method prior needs --prior hf:ORG/NAME (a monocular depth model)")
            # no semantic map, engine or precision: a spec, backend or --amp given with it would be ignored unread
            require_with("--method semattnet", False, "segment_spec", "backend", "amp")
        elif self.weights is None:
            raise click.UsageError("--checkpoint or --weights is required (or --method classical)")
        self.check_engine()

    def check_engine(self) -> None:
        """``--precision`` / ``--calibration`` / ``--amp`` / ``--backend`` / ``--device`` agree (:attr:`spec`)."""
        check_calibration(self.precision)
        if self.calibration is not None:
            check_calibration_frames(self.calibration)
        if self.method in ("classical", "prior"):
            if self.precision is not None:
                raise click.UsageError(f"--precision is the network's: --method {self.method} runs none")
            return
        from semattnet._utils.device import resolve_device

        resolve_device(self.device)  # a bad --device: one line (not a usage error), before any work
        _ = self.spec

    @functools.cached_property
    def spec(self) -> EngineSpec:
        """The engine spec of the options, resolved once (``--amp``'s one deprecation note printed here)."""
        from semattnet.inference.backends import EngineSpec

        spec = EngineSpec(self.backend, self.precision, self.device, self.calibration, self.amp)
        try:
            with warnings.catch_warnings(record=True) as notes:
                warnings.simplefilter("always", FutureWarning)
                resolved = spec.resolve()
        except SemAttNetError as exc:
            text = str(exc).replace("precision", "--precision", 1).replace("amp ", "--amp ")
            raise click.UsageError(text) from None
        finally:
            for note in {str(n.message) for n in notes if issubclass(n.category, FutureWarning)}:
                click.echo(f"note: {note}", err=True)
        return resolved

    def completer(self) -> Completer:
        """The one completer the options name: the classical baseline or the model of ``--weights`` on
        :attr:`spec`'s engine (:func:`semattnet.inference.completer.load_completer`)."""
        from semattnet.baselines.classical import ClassicalCompleter
        from semattnet.inference.completer import load_completer

        if self.method == "classical":
            return ClassicalCompleter()
        if self.method == "prior":
            from semattnet._utils.device import resolve_device
            from semattnet.baselines.prior import load_prior

            return load_prior(str(self.prior), str(resolve_device(self.device)))
        if self.weights is None:
            raise click.UsageError(
                "--checkpoint or --weights is required (they are one option: --checkpoint is an alias)"
            )
        return load_completer(self.weights, self.spec)
