"""Options under headings, and a command's parsed options as typed values.

click has no option groups: an option made with ``cls=section(HEADING)`` carries its heading, and a
:class:`SectionedCommand` prints its ``--help`` options heading by heading (in the order the headings first
appear). Elsewhere such an option is a plain :class:`click.Option`. :func:`values_of` reads the options a
dataclass names (its fields) out of the parsed ones, so a command hands typed values down, not ``**kwargs``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import fields
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import click

from semattnet.cli._group import Command

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "GeneratedCommand",
    "SectionOption",
    "SectionedCommand",
    "given",
    "rehelp",
    "section",
    "values_of",
    "with_options",
]

#: The heading of the options that name none (``--help``).
OTHER = "Other options"


class SectionOption(click.Option):
    """A click option shown under :attr:`heading` by a :class:`SectionedCommand` (made by :func:`section`)."""

    heading: ClassVar[str] = OTHER


@functools.cache
def section(heading: str) -> type[SectionOption]:
    """The option class of ``heading``: ``click.option(..., cls=section("Outputs"))``."""

    class Option(SectionOption):
        pass

    Option.heading = heading
    Option.__qualname__ = Option.__name__ = f"SectionOption[{heading}]"
    return Option


def heading_of(param: click.Parameter) -> str:
    """The heading ``param`` is listed under in a sectioned ``--help``."""
    return param.heading if isinstance(param, SectionOption) else OTHER


class SectionedCommand(Command):
    """A command whose ``--help`` lists its options under their headings."""

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        sections: dict[str, list[tuple[str, str]]] = {}
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx)
            if record is not None:
                sections.setdefault(heading_of(param), []).append(record)
        for heading, records in sections.items():
            with formatter.section(heading):
                formatter.write_dl(records)


class GeneratedCommand(SectionedCommand):
    """A sectioned command some of whose options are made from registries each time they are read, so that an
    entry registered after the command was made (a plugin's, a test's) is on it too. ``generated``: (after,
    make) pairs; ``make()`` gives options, inserted at the start (``after`` ``""``) or after the option named
    ``after``."""

    def __init__(
        self, *args: Any, generated: Sequence[tuple[str, Callable[[], Sequence[click.Parameter]]]] = (), **kwargs: Any
    ) -> None:
        super().__init__(*args, **kwargs)
        self._generated, self._static = tuple(generated), list(self.params)
        self.refresh()

    def refresh(self) -> None:
        """Make the generated options again (from the registries as they are now)."""
        params = list(self._static)
        for after, make in self._generated:
            at = 0 if not after else 1 + next(i for i, p in enumerate(params) if p.name == after)
            params[at:at] = make()
        self.params = params

    def get_params(self, ctx: click.Context) -> list[click.Parameter]:
        self.refresh()
        return super().get_params(ctx)


_F = TypeVar("_F", bound=Callable[..., object])


def with_options(options: Sequence[click.Parameter]) -> Callable[[_F], _F]:
    """A decorator giving a command ready-made options, listed in this order (as ``@click.option`` lines
    would: click collects them in the function's ``__click_params__``)."""

    def decorate(f: _F) -> _F:
        if isinstance(f, click.Command):  # above @command: the command's own list, in order
            f.params.extend(options)
            return f
        params: list[click.Parameter] = vars(f).setdefault("__click_params__", [])
        params.extend(reversed(options))
        return f

    return decorate


def given(ctx: click.Context, name: str) -> bool:
    """Whether the user gave option ``name`` (on the command line or in the environment), not its default."""
    return ctx.get_parameter_source(name) not in (None, click.core.ParameterSource.DEFAULT)


_D = TypeVar("_D", bound="DataclassInstance")


def values_of(cls: type[_D], params: Mapping[str, object]) -> _D:
    """The dataclass ``cls`` made from the parsed options its fields name."""
    return cls(**{f.name: params[f.name] for f in fields(cls)})


def rehelp(params: Sequence[click.Parameter], helps: Mapping[str, str]) -> list[click.Parameter]:
    """``params`` with the help of those named in ``helps`` (parameter name -> text) replaced, on copies: a shared
    option says what it does for the command it is on."""
    import copy

    out = []
    for p in params:
        if p.name in helps and isinstance(p, click.Option):
            p = copy.copy(p)
            p.help = helps[p.name]
        out.append(p)
    return out
