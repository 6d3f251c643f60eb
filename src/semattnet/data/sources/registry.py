"""The registry of frame sources, and the table ``predict``'s inputs are made from.

``@register_source(NAME, option=..., options=...)`` on a source class enrols it. ``options``: a
:class:`SourceOptions` dataclass, whose fields (with :func:`~semattnet._utils.registry.option` metadata) are the
source's command-line options, listed under its ``heading`` in ``predict --help``, and whose values build the
source (:meth:`SourceOptions.source`). Its class facts say what the frames offer the outputs.

:data:`SOURCES` imports the modules of this layer that hold its entries on first read; the ROS bag's source
enrols itself when :mod:`semattnet.robotics`, a layer above, is imported (``import semattnet`` does). Every
registered source runs through the suite in ``tests/registry/test_sources.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from semattnet._utils.registry import ClassRegistry
from semattnet.data.frames import IndexedSource

__all__ = ["SOURCES", "SourceOptions", "list_sources", "register_source"]

#: Source name -> :class:`~semattnet._utils.registry.Entry` (the class, the ``predict`` option making it and
#: the :class:`SourceOptions` of its options).
SOURCES: ClassRegistry[IndexedSource] = ClassRegistry(
    "source",
    homes=(
        "semattnet.data.sources.folder",
        "semattnet.data.sources.raw_drive",
        "semattnet.data.sources.kitti_split",
        "semattnet.data.datasets.nyuv2",
        "semattnet.data.datasets.void",
        "semattnet.data.datasets",
    ),
)


def register_source(
    name: str, option: str | None = None, options: type[SourceOptions] | None = None
) -> Callable[[type[IndexedSource]], type[IndexedSource]]:
    """Enrol a :class:`~semattnet.data.frames.IndexedSource` subclass as ``name`` (``option``: the CLI option
    making it; ``options``: its command-line options, see :class:`SourceOptions`)."""
    return SOURCES.register(name, option, options)


def list_sources() -> list[str]:
    """The registered source names."""
    return SOURCES.names()


@dataclass(frozen=True)
class SourceOptions:
    """The command-line options of one kind of input (its fields) and the source they build.

    Facts (class attributes): ``heading`` in ``--help``; ``selects``: the fields that choose this input;
    ``usage``: how the one-input rule names it; ``accepts``: the shared semantic-map options it takes
    (``semantic``: a file or folder of maps, ``segment_spec``: a segmenter); ``recording``: a timed recording of
    a camera and a LiDAR (point clouds, a bird's-eye view, a real-time replay); ``report``: the viewer can show
    its frames."""

    heading: ClassVar[str] = "Inputs"
    usage: ClassVar[str] = ""
    selects: ClassVar[tuple[str, ...]] = ()
    accepts: ClassVar[tuple[str, ...]] = ()
    recording: ClassVar[bool] = False
    report: ClassVar[bool] = False

    def check(self, segment_spec: str | None) -> None:
        """Options that do not go together (:class:`~semattnet._utils.registry.OptionError`), before any work
        (``segment_spec``: the segmenter asked for, or None)."""

    def listing(self) -> str | None:
        """What to print instead of a run (``--list-topics``), or None."""
        return None

    def has_intrinsics(self) -> bool:
        """Whether the frames come with the camera's intrinsics."""
        return True

    def reads_maps(self, semantic: Path | None) -> bool:
        """Whether the source reads the frames' semantic maps itself (``semantic``: the ``--semantic`` path)."""
        return semantic is not None

    def segment_split(self) -> tuple[str, Path, str] | None:
        """(dataset, root, split) when ``--segment`` segments the frames once into a cache folder read as
        ``semantic``, else None (the frames are segmented as they are read)."""
        return None

    def source(self, semantic: Path | None, log: Callable[[str], None]) -> IndexedSource:
        """The frames (``semantic``: the file or folder of their maps, or None; ``log``: where reports go)."""
        raise NotImplementedError  # every kind's options define it
