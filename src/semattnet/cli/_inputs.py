"""The inputs ``predict`` reads, generated from the source registry: each kind of input, its options and its source.

Each source entry of :data:`~semattnet.data.sources.registry.SOURCES` that declares its options (a
:class:`~semattnet.data.sources.registry.SourceOptions` dataclass) is a kind of input here: its fields are its
options (listed under its heading in ``predict --help``), its class facts say which options choose it, which
shared semantic-map options it takes and what it offers the outputs, and its values build the source. One rule
covers every kind (:func:`choose_input`): exactly one kind is chosen, and an option of another kind is a usage
error naming the kinds it belongs to. A source registered with its options gets them, its heading and the rule
with no other code.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from semattnet._utils.registry import Option, OptionError
from semattnet.cli._model import palette_mismatch_option
from semattnet.cli._options import DEPTH_M, PIXELS, SECONDS, SPEED
from semattnet.cli._params import given, section, values_of, with_options
from semattnet.data.sources.registry import SOURCES, SourceOptions

if TYPE_CHECKING:
    from semattnet.data.frames import IndexedSource
    from semattnet.inference.semantic import SemanticMaps

__all__ = [
    "INPUTS",
    "ChosenInput",
    "InputKind",
    "Maps",
    "choose_input",
    "field_options",
    "input_options",
    "or_list",
    "usage_error",
]

SEMANTIC = "Semantic maps"
_INPUT = click.Path(exists=True, path_type=Path)
_F = TypeVar("_F", bound=Callable[..., object])


def or_list(items: Sequence[str]) -> str:
    """``a``, ``a or b``, ``a, b or c``."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} or {items[-1]}"


class Address(click.ParamType):
    """``--live`` / ``--rerun-serve``: ``[HOST:]PORT`` (:func:`semattnet.robotics.gate.parse_address`), returned
    as given; a malformed one is a one-line usage error."""

    name = "[HOST:]PORT"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> str:
        from semattnet._errors import InputError
        from semattnet.robotics.gate import parse_address

        try:
            parse_address(str(value), "address")
        except InputError as exc:
            self.fail(str(exc), param, ctx)
        return str(value)


#: What an :class:`~semattnet._utils.registry.Option`'s ``type`` names: an existing input (file or folder), an
#: existing folder or file, an output folder, file or path, seconds, metres, pixels, a speed factor, a server's
#: ``[HOST:]PORT``.
TYPES: dict[str, click.ParamType | None] = {
    "text": None,
    "input": _INPUT,
    "folder": click.Path(exists=True, file_okay=False, path_type=Path),
    "file": click.Path(exists=True, dir_okay=False, path_type=Path),
    "out-folder": click.Path(file_okay=False, path_type=Path),
    "out-file": click.Path(dir_okay=False, path_type=Path),
    "out-path": click.Path(path_type=Path),
    "seconds": SECONDS,
    "metres": DEPTH_M,
    "pixels": PIXELS,
    "speed": SPEED,
    "address": Address(),
}


def usage_error(exc: OptionError) -> click.UsageError:
    """An :class:`~semattnet._utils.registry.OptionError` as click reports a usage error (exit status 2)."""
    return click.BadParameter(str(exc), param_hint=exc.option) if exc.option else click.UsageError(str(exc))


def _click_option(name: str, spec: Option, default: object, heading: str) -> click.Option:
    kw: dict[str, Any] = {"help": spec.help, "metavar": spec.metavar, "show_default": spec.show_default}
    if spec.type == "flag":
        kw["is_flag"] = True
    elif spec.flag_value is not None:
        kw.update(is_flag=False, flag_value=spec.flag_value, default=default, type=TYPES[spec.type])
    else:
        kw.update(type=click.Choice(spec.choices) if spec.type == "choice" else TYPES[spec.type], default=default)
    return section(heading)([*spec.flags, name], **kw)


def field_options(cls: type, heading: str) -> tuple[click.Option, ...]:
    """The click options of a dataclass whose fields carry :func:`~semattnet._utils.registry.option` metadata,
    under ``heading``, in field order."""
    return tuple(
        _click_option(f.name, f.metadata["option"], f.default, heading) for f in fields(cls) if "option" in f.metadata
    )


@dataclass(frozen=True)
class Maps:
    """Where the semantic maps come from: ``--semantic`` (files), ``--segment`` (a segmenter SPEC) and what to do
    with maps of another palette (``--palette-mismatch``)."""

    semantic: Path | None
    segment_spec: str | None
    palette_mismatch: str

    def semantic_maps(self, folder: bool) -> SemanticMaps:
        """The maps' filler of a source that reads maps from a folder (``folder``) or none."""
        from semattnet.inference.semantic import SemanticMaps

        return SemanticMaps(self.segment_spec, folder=folder, mismatch=self.palette_mismatch)


#: The semantic-map options: --semantic and --segment belong to the kinds whose ``accepts`` names them.
MAP_OPTIONS = (
    section(SEMANTIC)(
        ["--semantic"],
        type=_INPUT,
        default=None,
        help="PNG file or folder of colour-coded semantic maps (with --rgb, --kitti-raw or --data).",
    ),
    section(SEMANTIC)(
        ["--segment", "segment_spec"],
        default=None,
        metavar="SPEC",
        help="With --kitti-raw or --bag: segment each image with this model (see `semattnet segment "
        "--model`); with --data (nyuv2, void): the split's frames segmented once into a cache folder "
        "and reused.",
    ),
    palette_mismatch_option(section(SEMANTIC)),
)


@dataclass(frozen=True)
class InputKind:
    """One kind of input: a source ``name`` and its options' dataclass ``values`` (with the facts: heading,
    ``selects``, ``usage``, ``accepts``, ``recording``, ``report``; see
    :class:`~semattnet.data.sources.registry.SourceOptions`); ``options``: its click options."""

    name: str
    values: type[SourceOptions]

    @property
    def options(self) -> tuple[click.Option, ...]:
        return _kind_options(self.values)

    @property
    def usage(self) -> str:
        return self.values.usage

    @property
    def selects(self) -> tuple[str, ...]:
        return self.values.selects

    @property
    def accepts(self) -> tuple[str, ...]:
        return self.values.accepts

    @property
    def recording(self) -> bool:
        return self.values.recording

    @property
    def report(self) -> bool:
        return self.values.report

    @property
    def flag(self) -> str:
        """The option naming this kind in errors (``--rgb``)."""
        return next(o.opts[0] for o in self.options if o.name == self.selects[0])

    def takes(self, name: str) -> bool:
        """Whether option ``name`` means something with this kind."""
        return name in self.accepts or any(o.name == name for o in self.options)


_CACHE: dict[type, tuple[click.Option, ...]] = {}


def _kind_options(values: type[SourceOptions]) -> tuple[click.Option, ...]:
    """A kind's click options, made once (the command and the rules share the same objects)."""
    if values not in _CACHE:
        _CACHE[values] = field_options(values, values.heading)
    return _CACHE[values]


def input_kinds() -> tuple[InputKind, ...]:
    """Every registered source with options, in the registry's order: the kinds of input ``predict`` reads."""
    return tuple(InputKind(e.name, e.options) for e in SOURCES.values() if e.options is not None)


#: Every kind of input ``predict`` reads, in the order of its ``--help`` (the registry's, when this was imported).
INPUTS: tuple[InputKind, ...] = input_kinds()


def input_options(kinds: Sequence[InputKind] | None = None) -> Callable[[_F], _F]:
    """The options of every kind in ``kinds`` (default: every registered one), then the semantic-map options,
    under their headings."""
    return with_options([*input_params(kinds), *MAP_OPTIONS])


def input_params(kinds: Sequence[InputKind] | None = None) -> list[click.Option]:
    """The options of every kind in ``kinds`` (default: every registered one, now)."""
    return [o for kind in (input_kinds() if kinds is None else kinds) for o in kind.options]


@dataclass(frozen=True)
class ChosenInput:
    """The kind of input the options chose, its checked values and the semantic-map options."""

    kind: InputKind
    values: SourceOptions
    maps: Maps

    def open(self, device: str) -> tuple[IndexedSource, SemanticMaps]:
        """The source and the filler of its missing semantic maps (with ``--segment``, a dataset split's maps
        segmented once on ``device`` into a cache folder and read as a folder)."""
        maps, values = self.maps, self.values
        split = values.segment_split() if maps.segment_spec is not None and maps.semantic is None else None
        if split is not None:
            from semattnet.segmentation.datasets import segment_split

            dataset, root, name = split
            spec = str(maps.segment_spec)  # given: split is not None
            folder = segment_split(dataset, root, (name,), spec, device, log=click.echo)
            return values.source(folder, click.echo), Maps(None, None, maps.palette_mismatch).semantic_maps(True)
        filler = maps.semantic_maps(folder=values.reads_maps(maps.semantic))
        return values.source(maps.semantic, click.echo), filler


def choose_input(ctx: click.Context, kinds: Sequence[InputKind] | None = None) -> ChosenInput:
    """Exactly one kind of input, no option of another kind, then the kind's own checks (usage errors)."""
    kinds = input_kinds() if kinds is None else kinds
    chosen = [kind for kind in kinds if any(given(ctx, name) for name in kind.selects)]
    if len(chosen) != 1:
        several = f" (one of them: not {' and '.join(k.flag for k in chosen)})" if chosen else ""
        raise click.UsageError("give " + ", or ".join(k.usage for k in kinds) + several)
    kind = chosen[0]
    flags = {p.name: p.opts[0] for p in ctx.command.get_params(ctx)}
    for name in dict.fromkeys(n for k in kinds for n in (*(str(o.name) for o in k.options), *k.accepts)):
        if given(ctx, name) and not kind.takes(name):
            owners = [k.flag for k in kinds if k.takes(name)]
            raise click.UsageError(f"{flags.get(name, name)} is an option of {or_list(owners)}, not of {kind.flag}")
    picked = ChosenInput(kind, values_of(kind.values, ctx.params), values_of(Maps, ctx.params))
    try:
        picked.values.check(picked.maps.segment_spec)
    except OptionError as exc:
        raise usage_error(exc) from None
    return picked
