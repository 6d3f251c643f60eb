"""A named registry of classes: what a decorator line enrols (the sources and sinks of the frame loop).

    >>> from semattnet._utils.registry import Registry
    >>> THINGS: Registry[object] = Registry("thing")
    >>> @THINGS.register("plain", option="--plain")
    ... class Plain:
    ...     pass
    >>> THINGS.names(), THINGS["plain"].option
    (['plain'], '--plain')

An entry may declare its command-line options (``options``: a dataclass whose fields carry :func:`option`
metadata; the command builds its click options from them, so a field is an option in one line) and hand the
parsed values back to build itself. A registry lists ``homes``, the modules its entries live in, and imports
them on first read, so that every entry is listed without its module imported first (an entry registered in
another module, e.g. a test's, comes after them).

Registering an entry enrols it in the test suites over its registry (``tests/registry/``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Generic, TypeVar

from semattnet._errors import InputError

__all__ = ["Entry", "Option", "OptionError", "Registry", "UnknownEntryError", "option", "volatile"]

T = TypeVar("T")


class UnknownEntryError(InputError):
    """A name that is not in a registry."""


class OptionError(InputError):
    """Options of an entry that do not go together, or the bad value of ``option`` (the command reports it as a
    usage error)."""

    def __init__(self, message: str, option: str | None = None) -> None:
        super().__init__(message)
        self.option = option


@dataclass(frozen=True)
class Option:
    """One command-line option of a dataclass field: its ``flags``, ``help`` and ``type`` (a name the command
    turns into its parameter type: ``text``, ``flag``, ``choice`` (of ``choices``), or one of the command's
    path, duration and range types: ``input``, ``folder``, ``file``, ``seconds``, ...); ``metavar``,
    ``show_default``; ``flag_value``: an option whose value may be left out; ``identity``: whether the option
    changes what a run writes (a resumed run must agree with the first in those)."""

    flags: tuple[str, ...]
    help: str
    type: str = "text"
    choices: tuple[str, ...] = ()
    metavar: str | None = None
    show_default: bool = False
    flag_value: str | None = None
    identity: bool = True


def option(*flags: str, help: str, default: object = None, **kw: Any) -> Any:
    """A dataclass ``field`` that is the command-line option ``flags`` (see :class:`Option`); ``type="flag"``
    defaults to False."""
    spec = Option(tuple(flags), help, **kw)
    return field(default=False if spec.type == "flag" and default is None else default, metadata={"option": spec})


def volatile(cls: type) -> set[str]:
    """The fields of the dataclass ``cls`` whose options do not change what a run writes (``identity=False``)."""
    return {f.name for f in fields(cls) if "option" in f.metadata and not f.metadata["option"].identity}


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One registered class: its ``name``, the class and the command-line ``option`` that makes it (None: the
    library only); ``options``: the dataclass of its own command-line options (None: it has none);
    ``summary``: the first line of the class's docstring."""

    name: str
    cls: type[T]
    option: str | None = None
    options: type | None = None

    @property
    def summary(self) -> str:
        return (self.cls.__doc__ or "").strip().splitlines()[0] if self.cls.__doc__ else ""


class Registry(Mapping[str, Entry[T]]):
    """Name -> :class:`Entry`; ``kind`` names the things in errors; ``homes``: the modules that register its
    entries, imported on first read; entries are listed in the order of their homes, then of registration."""

    def __init__(self, kind: str, homes: Sequence[str] = ()) -> None:
        self.kind = kind
        self.homes = tuple(homes)
        self._entries: dict[str, Entry[T]] = {}
        self._options: dict[str, type] = {}
        self._loaded = not self.homes

    def register(self, name: str, option: str | None = None,
                 options: type | None = None) -> Callable[[type[T]], type[T]]:  # fmt: skip
        """A class decorator enrolling the class as ``name`` (a second class under one name is refused)."""

        def enrol(cls: type[T]) -> type[T]:
            old = self._entries.get(name)
            if old is not None and old.cls.__qualname__ != cls.__qualname__:
                raise InputError(f"{self.kind} {name!r}: already registered as {old.cls.__qualname__}")
            self._entries[name] = Entry(name, cls, option, options or self._options.get(name))
            return cls

        return enrol

    def attach(self, name: str, options: type) -> None:
        """Give entry ``name`` (registered before or after) the command-line ``options``: for options declared
        in a module the entry's own cannot import."""
        self._options[name] = options
        if name in self._entries:
            e = self._entries[name]
            self._entries[name] = Entry(e.name, e.cls, e.option, options)

    def unregister(self, name: str) -> None:
        """Remove entry ``name`` (a test's own entry, once the test is done)."""
        self._entries.pop(name, None)

    def _all(self) -> dict[str, Entry[T]]:
        if not self._loaded:
            self._loaded = True  # before the imports: a home reading the registry sees what is there
            for home in self.homes:
                importlib.import_module(home)
        rank = {home: i for i, home in enumerate(self.homes)}
        order = sorted(self._entries.values(), key=lambda e: rank.get(e.cls.__module__, len(rank)))
        return {e.name: e for e in order}

    def names(self) -> list[str]:
        """The registered names, in order."""
        return list(self._all())

    def __getitem__(self, name: str) -> Entry[T]:
        entries = self._all()
        if name not in entries:
            raise UnknownEntryError(f"unknown {self.kind} {name!r}; registered: {', '.join(entries)}")
        return entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"
