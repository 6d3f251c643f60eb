"""The registry of frame sources: ``@register_source(NAME, option=...)`` on a source class enrols it.

The robot sources register from :mod:`semattnet.robotics` (which imports this layer, never the reverse), so
they are listed once their module is imported. Every registered source runs through the suite in
``tests/registry/test_sources.py``.
"""

from __future__ import annotations

from collections.abc import Callable

from semattnet._utils.registry import Registry
from semattnet.data.frames import IndexedSource

__all__ = ["SOURCES", "list_sources", "register_source"]

#: Source name -> :class:`~semattnet._utils.registry.Entry` (the class and the ``predict`` option making it).
SOURCES: Registry[IndexedSource] = Registry("source")


def register_source(name: str, option: str | None = None) -> Callable[[type[IndexedSource]], type[IndexedSource]]:
    """Enrol a :class:`~semattnet.data.frames.IndexedSource` subclass as ``name`` (``option``: the CLI option)."""
    return SOURCES.register(name, option)


def list_sources() -> list[str]:
    """The registered source names (the robot ones once :mod:`semattnet.robotics`' modules are imported)."""
    return SOURCES.names()
