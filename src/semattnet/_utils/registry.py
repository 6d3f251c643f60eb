"""A named registry of classes: what a decorator line enrols (the sources and sinks of the frame loop).

    >>> from semattnet._utils.registry import Registry
    >>> THINGS: Registry[object] = Registry("thing")
    >>> @THINGS.register("plain", option="--plain")
    ... class Plain:
    ...     pass
    >>> THINGS.names(), THINGS["plain"].option
    (['plain'], '--plain')

Registering an entry enrols it in the test suites over its registry (``tests/registry/``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Generic, TypeVar

from semattnet._errors import InputError

__all__ = ["Entry", "Registry", "UnknownEntryError"]

T = TypeVar("T")


class UnknownEntryError(InputError):
    """A name that is not in a registry."""


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One registered class: its ``name``, the class and the command-line ``option`` that makes it (None: the
    library only); ``summary``: the first line of the class's docstring."""

    name: str
    cls: type[T]
    option: str | None = None

    @property
    def summary(self) -> str:
        return (self.cls.__doc__ or "").strip().splitlines()[0] if self.cls.__doc__ else ""


class Registry(Mapping[str, Entry[T]]):
    """Name -> :class:`Entry`, in the order of registration; ``kind`` names the things in errors."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._entries: dict[str, Entry[T]] = {}

    def register(self, name: str, option: str | None = None) -> Callable[[type[T]], type[T]]:
        """A class decorator enrolling the class as ``name`` (a second class under one name is refused)."""

        def enrol(cls: type[T]) -> type[T]:
            old = self._entries.get(name)
            if old is not None and old.cls.__qualname__ != cls.__qualname__:
                raise InputError(f"{self.kind} {name!r}: already registered as {old.cls.__qualname__}")
            self._entries[name] = Entry(name, cls, option)
            return cls

        return enrol

    def names(self) -> list[str]:
        """The registered names, in the order of registration."""
        return list(self._entries)

    def __getitem__(self, name: str) -> Entry[T]:
        if name not in self._entries:
            raise UnknownEntryError(f"unknown {self.kind} {name!r}; registered: {', '.join(self._entries)}")
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {self.names()})"
