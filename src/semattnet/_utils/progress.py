"""One home for progress bars: a tqdm bar only when its stream is a terminal.

Written to a log file (``semattnet demo > log``) a tqdm bar writes every refresh, carriage returns
and all; :func:`progress` turns the bar off unless the stream is a TTY (or ``force=True``), and
:func:`is_interactive` tells callers to log one line per epoch instead.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterable
from typing import IO

from tqdm import tqdm

__all__ = ["is_interactive", "progress"]


class _Bar(tqdm):
    """tqdm with a thread lock of its own.

    tqdm's default lock includes a multiprocessing semaphore, made on first use; a process that forked
    (a data-loader worker, a test runner's worker) can abort inside it. Our bars are written by one
    process's threads, so a thread lock is all they need, and tqdm's own class keeps its lock for others.
    """

    _lock = threading.RLock()


def is_interactive(stream: IO[str] | None = None) -> bool:
    """Whether ``stream`` (default ``sys.stderr``, where tqdm writes) is a terminal."""
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except (ValueError, OSError):  # a closed or detached stream
        return False


def progress(
    iterable: Iterable[object] | None = None,
    *,
    enabled: bool = True,
    force: bool | None = None,
    file: IO[str] | None = None,
    total: int | None = None,
    initial: int = 0,
    desc: str | None = None,
    unit: str = "it",
    leave: bool = True,
    dynamic_ncols: bool = False,
    mininterval: float = 0.1,
) -> tqdm:
    """A ``tqdm`` bar over ``iterable`` (or a manual one with ``total=``), shown only where it belongs.

    Args:
        iterable: what to iterate (None: update the bar by hand).
        enabled: False hides the bar whatever the stream (e.g. not the main process, ``progress=False``).
        force: True shows the bar even when ``file`` is not a terminal, False never; None: only on a terminal.
        file: the stream (default ``sys.stderr``).
        total: the number of steps (None: ``len(iterable)`` where it has one).
        initial: the steps already done (a resumed epoch).
        desc: the bar's label.
        unit: the name of one step.
        leave: keep the finished bar on screen.
        dynamic_ncols: follow the terminal's width.
        mininterval: the least seconds between two refreshes.
    """
    stream = sys.stderr if file is None else file
    shown = enabled and (force if force is not None else is_interactive(stream))
    return _Bar(
        iterable,
        file=stream,
        disable=not shown,
        total=total,
        initial=initial,
        desc=desc,
        unit=unit,
        leave=leave,
        dynamic_ncols=dynamic_ncols,
        mininterval=mininterval,
    )
