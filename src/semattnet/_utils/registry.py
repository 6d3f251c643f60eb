"""The one registry shape: a named table of things (models, encoders, weights, engines, datasets, frame sources,
output sinks), each enrolled by one line where it is defined.

    >>> from semattnet._utils.registry import ClassRegistry, Registry
    >>> SIZES: Registry[int] = Registry("size")
    >>> SIZES.add("small", 1), SIZES["small"], SIZES.names()
    (1, 1, ['small'])
    >>> THINGS: ClassRegistry[object] = ClassRegistry("thing")
    >>> @THINGS.register("plain", option="--plain")
    ... class Plain:
    ...     pass
    >>> THINGS.names(), THINGS["plain"].option
    (['plain'], '--plain')

Every table refuses a second entry under a taken name and answers an unknown name with one
:class:`UnknownEntryError` line that lists the names (and aliases). A :class:`ClassRegistry` holds classes
(:class:`Entry`: the class, the command-line option that makes it and the dataclass of its own options, whose fields
carry :func:`option` metadata, so a field is an option in one line). A registry may list ``homes``: modules of its
own layer or below (a test checks it) imported on first read, so every built-in entry is listed without its module
imported first; a layer above enrols its own entries when it is imported (``semattnet.robotics`` its source and
sinks).

Registering an entry enrols it in the test suites over its registry (``tests/registry/``).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Generic, TypeVar

from semattnet._errors import InputError

__all__ = [
    "ClassRegistry",
    "DuplicateEntryError",
    "Entry",
    "Option",
    "OptionError",
    "Registry",
    "UnknownEntryError",
    "option",
    "volatile",
]

T = TypeVar("T")
C = TypeVar("C")


class UnknownEntryError(InputError):
    """A name that is not in a registry (the message lists the names)."""


class DuplicateEntryError(InputError):
    """A second entry under a name a registry already holds."""


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


class Registry(Mapping[str, T]):
    """Name -> entry. ``kind`` names the things in messages; ``homes``: the modules that enrol the built-in entries,
    imported on first read; ``home_of``: the module an entry comes from, to list the homes' entries first, in the
    homes' order (then the others, in the order of registration; without it, all in the order of registration).

    Aliases (:meth:`alias`) are accepted wherever a name is (``registry[alias]``, ``alias in registry``), but
    iteration, ``len`` and :meth:`names` give each entry once."""

    def __init__(self, kind: str, homes: Sequence[str] = (), home_of: Callable[[T], str] | None = None) -> None:
        self.kind = kind
        self.homes = tuple(homes)
        self._home_of = home_of
        self._entries: dict[str, T] = {}
        self._aliases: dict[str, str] = {}
        self._loaded = not self.homes

    def add(self, name: str, entry: T, *, replace: bool = False) -> T:
        """Enrol ``entry`` as ``name`` and give it back; a taken name is refused unless ``replace``."""
        taken = name in self._entries or name in self._aliases
        if taken and not replace and not self._same(self._entries.get(name), entry):
            raise DuplicateEntryError(f"{self.kind} {name!r} is already registered")
        self._entries[name] = entry
        return entry

    def _same(self, old: T | None, new: T) -> bool:
        """Whether ``new`` is ``old`` enrolled again, which is allowed (a value never is: a second record of one
        name is refused, whatever it holds)."""
        return False

    def alias(self, alias: str, name: str) -> None:
        """Let ``alias`` stand for the entry ``name``."""
        if alias in self._entries or self._aliases.get(alias, name) != name:
            raise DuplicateEntryError(f"{self.kind} alias {alias!r} is already taken")
        self._aliases[alias] = name

    def remove(self, name: str) -> None:
        """Remove entry ``name`` and its aliases (a plugin's or a test's own, once done)."""
        self._entries.pop(name, None)
        self._aliases = {a: n for a, n in self._aliases.items() if n != name}

    @property
    def aliases(self) -> Mapping[str, str]:
        """Alias -> the name it stands for."""
        self._load()
        return dict(self._aliases)

    def resolve(self, name: str) -> str:
        """The registered name ``name`` stands for (itself, or what the alias stands for).

        Raises:
            UnknownEntryError: one line listing the names (and aliases).
        """
        entries = self._ordered()
        if isinstance(name, str) and name in entries:
            return name
        if isinstance(name, str) and name in self._aliases:
            return self._aliases[name]
        listing = ", ".join(entries) or "(none)"
        more = f" (aliases: {', '.join(self._aliases)})" if self._aliases else ""
        raise UnknownEntryError(f"unknown {self.kind} {name!r}; available: {listing}{more}")

    def names(self) -> list[str]:
        """The registered names, in order."""
        return list(self._ordered())

    def _load(self) -> None:
        if not self._loaded:
            self._loaded = True  # before the imports: a home reading the registry sees what is there
            for home in self.homes:
                importlib.import_module(home)

    def _ordered(self) -> dict[str, T]:
        self._load()
        if self._home_of is None:
            return self._entries
        home_of, rank = self._home_of, {home: i for i, home in enumerate(self.homes)}
        order = sorted(self._entries, key=lambda name: rank.get(home_of(self._entries[name]), len(rank)))
        return {name: self._entries[name] for name in order}

    def __getitem__(self, name: str) -> T:
        return self._ordered()[self.resolve(name)]

    def get(self, name: str, default: T | None = None) -> T | None:  # type: ignore[override]
        """The entry ``name`` stands for, else ``default``."""
        return self[name] if name in self else default

    def __contains__(self, name: object) -> bool:
        entries = self._ordered()
        return isinstance(name, str) and (name in entries or name in self._aliases)

    def __iter__(self) -> Iterator[str]:
        return iter(self._ordered())

    def __len__(self) -> int:
        return len(self._ordered())

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.kind!r}, {self.names()})"


@dataclass(frozen=True)
class Entry(Generic[C]):
    """One registered class: its ``name``, the class and the command-line ``option`` that makes it (None: the
    library only); ``options``: the dataclass of its own command-line options (None: it has none);
    ``summary``: the first line of the class's docstring."""

    name: str
    cls: type[C]
    option: str | None = None
    options: type | None = None

    @property
    def summary(self) -> str:
        return (self.cls.__doc__ or "").strip().splitlines()[0] if self.cls.__doc__ else ""


class ClassRegistry(Registry[Entry[C]]):
    """A :class:`Registry` of classes, enrolled by a decorator line (:meth:`register`), listed in the order of
    their homes, then of registration."""

    def __init__(self, kind: str, homes: Sequence[str] = ()) -> None:
        super().__init__(kind, homes, home_of=_module_of)
        self._options: dict[str, type] = {}

    def register(
        self, name: str, option: str | None = None, options: type | None = None
    ) -> Callable[[type[C]], type[C]]:
        """A class decorator enrolling the class as ``name`` (a second class under one name is refused)."""

        def enrol(cls: type[C]) -> type[C]:
            self.add(name, Entry(name, cls, option, options or self._options.get(name)))
            return cls

        return enrol

    def _same(self, old: Entry[C] | None, new: Entry[C]) -> bool:
        return old is not None and old.cls.__qualname__ == new.cls.__qualname__

    def attach(self, name: str, options: type) -> None:
        """Give entry ``name`` (registered before or after) the command-line ``options``: for options declared
        in a module the entry's own cannot import."""
        self._options[name] = options
        if name in self._entries:
            e = self._entries[name]
            self._entries[name] = Entry(e.name, e.cls, e.option, options)


def _module_of(entry: Entry[Any]) -> str:
    return entry.cls.__module__
