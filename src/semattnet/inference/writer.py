"""The frame loop's write stage: what the loop does with a completed frame (the sinks, moving its files into
place, the journal) run in a background thread, a bounded number of frames behind the network.

:class:`WriteStage` runs the tasks it is handed in order, one at a time, in one thread, so the outputs and the
journal see the frames in the order the loop completed them. ``depth`` frames at most are handed and not yet
written; handing one more waits (back-pressure: memory stays bounded, and a paced replay counts the frames
that arrive meanwhile as dropped). ``depth=0`` runs each task at once, in the caller's thread (the serial loop).

The first error a task raises stops the stage (the tasks after it are not run) and is raised in the caller's
thread by the next :meth:`~WriteStage.submit` or :meth:`~WriteStage.drain`. Leaving the stage's ``with`` block
on the caller's error (Ctrl-C, SIGTERM, a frame that stops the run) first lets the frames already handed be
written, so the journal records them, then joins the thread: none is left behind.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from types import TracebackType

__all__ = ["WriteStage"]

Task = Callable[[], None]


class WriteStage:
    """Tasks run in order in a background thread, at most ``depth`` frame tasks handed and not done (module doc).

    ``waited_s``: how long :meth:`submit` waited for the stage (the loop held up by the writing)."""

    def __init__(self, depth: int, name: str = "semattnet-writer") -> None:
        self.depth = depth
        self.waited_s = 0.0
        self._cond = threading.Condition()
        self._tasks: deque[tuple[Task, bool]] = deque()
        self._frames = 0  # frame tasks handed and not done (queued or running)
        self._busy = False
        self._stopped = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name=name, daemon=True) if depth > 0 else None

    def __enter__(self) -> WriteStage:
        if self._thread is not None:
            self._thread.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        try:
            if exc is None:
                self.drain()
            else:  # the caller's error: the frames handed are written first (their journal entries)
                self._settle()
        finally:
            self.close()

    def submit(self, task: Task, frame: bool = True) -> None:
        """Run ``task`` after those handed before; ``frame``: it holds a frame (counted against ``depth``; a
        note, e.g. a frame skipped, never waits). Raises the stage's error, if one stopped it."""
        if self._thread is None:
            task()
            return
        with self._cond:
            t0 = time.perf_counter()
            while frame and self._frames >= self.depth and self._error is None:
                self._cond.wait()
            self.waited_s += time.perf_counter() - t0
            self._raise()
            self._tasks.append((task, frame))
            self._frames += frame
            self._cond.notify_all()

    def drain(self) -> None:
        """Wait until every task handed is done; raise the stage's error, if one stopped it."""
        with self._cond:
            while (self._tasks or self._busy) and self._error is None:
                self._cond.wait()
            self._raise()

    def close(self) -> None:
        """Stop the thread once its current task is done (tasks not started are dropped) and join it."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join()

    def _settle(self) -> None:
        """:meth:`drain`, the stage's own error left to the caller's (which is being raised)."""
        try:
            self.drain()
        except Exception:
            pass

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error

    def _work(self) -> None:
        while True:
            with self._cond:
                while not self._tasks and not self._stopped:
                    self._cond.wait()
                if self._stopped:
                    return
                task, frame = self._tasks.popleft()
                self._busy = True
            try:
                task()
            except BaseException as exc:  # handed to the caller's thread
                with self._cond:
                    self._error, self._busy = exc, False
                    self._tasks.clear()
                    self._cond.notify_all()
                return
            with self._cond:
                self._busy = False
                self._frames -= frame
                self._cond.notify_all()
