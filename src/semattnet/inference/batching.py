"""Batching in the one frame loop (:func:`semattnet.inference.feed.completions`, ``batch_size`` > 1): runs of
consecutive frames of one size, completed in one engine call (a completer with ``check_frame`` and
``complete_batch``, as :class:`~semattnet.inference.DepthCompleter`)."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager
from typing import Protocol, TypeVar, runtime_checkable

import numpy as np

from semattnet.data.frames import Frame
from semattnet.inference.contract import Completion

__all__ = ["BatchCompleter", "complete_group", "groups"]

T = TypeVar("T")


@runtime_checkable
class BatchCompleter(Protocol):
    """A completer that checks one frame and completes frames of one size in one call."""

    def check_frame(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> object: ...

    def complete_batch(
        self, frames: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray | None]]
    ) -> list[Completion]: ...


class Timer(Protocol):
    """What batching needs of :class:`~semattnet.inference.timing.StageTimes`."""

    def time(self, name: str, stage: str) -> AbstractContextManager[None]: ...

    def share(self, name: str, names: Sequence[str], stages: Sequence[str]) -> None: ...


def groups(items: Iterator[T], size: int) -> Iterator[list[T]]:
    """``items`` in runs of at most ``size`` consecutive frames of one size; anything else (a fault) alone."""
    group: list[T] = []
    first: tuple[int, int] | None = None
    for item in items:
        frame = item.size if isinstance(item, Frame) else None
        if group and (frame is None or frame != first):
            yield group
            group = []
        if frame is None:
            yield [item]
            continue
        first = frame if not group else first
        group.append(item)
        if len(group) == size:  # full: out at once, without reading the next item (read-ahead stays bounded)
            yield group
            group = []
    if group:
        yield group


def complete_group(
    completer: BatchCompleter,
    group: Sequence[Frame],
    timer: Timer,
    current: list[str],
    fault: Callable[[Frame, Exception], None],
) -> Iterator[tuple[Frame, Completion]]:
    """Frames of one size through ``completer.complete_batch`` in one call: each checked first (``fault`` gets a
    frame whose check raised), the call timed as ``network`` and its times shared out evenly over the frames."""
    ok = []
    for frame in group:
        try:
            completer.check_frame(frame.rgb, frame.sparse, frame.semantic)
            ok.append(frame)
        except Exception as exc:
            fault(frame, exc)
    if not ok:
        return
    current[0] = ok[0].name
    with timer.time(ok[0].name, "network"):
        done = completer.complete_batch([(f.rgb, f.sparse, f.semantic) for f in ok])
    timer.share(ok[0].name, [f.name for f in ok], ("network", "propagation"))
    yield from zip(ok, done, strict=True)
