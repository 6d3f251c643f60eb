"""The registry of output sinks: ``@register_sink(NAME, option=...)`` on a sink class enrols it.

The robot sinks register from :mod:`semattnet.robotics` (which imports this layer, never the reverse), so
they are listed once their module is imported. Every registered sink runs through the suite in
``tests/registry/test_sinks.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from semattnet._utils.registry import Registry

if TYPE_CHECKING:
    from semattnet.inference.sinks import Sink

__all__ = ["SINKS", "list_sinks", "register_sink"]

#: Sink name -> :class:`~semattnet._utils.registry.Entry` (the class and the ``predict`` option asking for it).
SINKS: Registry[Sink] = Registry("sink")


def register_sink(name: str, option: str | None = None) -> Callable[[type[Sink]], type[Sink]]:
    """Enrol a :class:`~semattnet.inference.sinks.Sink` subclass as ``name`` (``option``: the CLI option)."""
    return SINKS.register(name, option)


def list_sinks() -> list[str]:
    """The registered sink names (the robot ones once :mod:`semattnet.robotics`' modules are imported)."""
    return SINKS.names()
