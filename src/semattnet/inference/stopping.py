"""Stopping a frame run from outside: SIGTERM handled as Ctrl-C is, so the frames already handed to the writer are
written and journaled before the process exits (:mod:`~semattnet.inference.pipeline`)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["SIGTERM_EXIT", "terminate_as_exit"]

#: The exit status of a run stopped by SIGTERM (the shell's 128 + the signal's number).
SIGTERM_EXIT = 128 + signal.SIGTERM


@contextmanager
def terminate_as_exit() -> Iterator[None]:
    """While active, SIGTERM (when it would kill the process at once) raises ``SystemExit`` in the main thread,
    so a terminated run stops as Ctrl-C does: the frames handed to the writer written, the journal saved."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        yield
        return

    def stop(signum: int, frame: object) -> None:
        raise SystemExit(SIGTERM_EXIT)

    signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
