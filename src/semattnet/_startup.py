"""A Ctrl-C while the ``semattnet`` command starts is one line, not a traceback.

Importing the package takes seconds (torch); Python's own handler would raise ``KeyboardInterrupt`` in the
middle of an import and print its traceback. When this process is the command line (``semattnet ...`` or
``python -m semattnet ...``, never a program importing the library), importing this module (the package's
first import, before torch) calls :func:`quiet_interrupts`: SIGINT then says ``Aborted!`` (click's word for
it) and exits with status 1. :func:`restore_interrupts` puts Python's handler back once the command line
takes over (click says the same for an interrupt from there on, and the commands handle their own).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path
from types import FrameType

__all__ = ["quiet_interrupts", "restore_interrupts"]


def _is_command_line() -> bool:
    """Whether this process runs the ``semattnet`` command (its console script, or ``python -m semattnet``)."""
    argv = list(getattr(sys, "orig_argv", []))
    if any(argv[i : i + 2] == ["-m", "semattnet"] for i in range(len(argv))):
        return True
    return bool(sys.argv) and Path(sys.argv[0]).name in ("semattnet", "semattnet.exe", "semattnet-script.py")


def _aborted(signum: int, frame: FrameType | None) -> None:
    os.write(2, b"Aborted!\n")
    os._exit(1)


def quiet_interrupts() -> None:
    """In the command line's process, with Python's handler in place: SIGINT is one line and exit status 1."""
    if threading.current_thread() is not threading.main_thread() or not _is_command_line():
        return
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _aborted)


def restore_interrupts() -> None:
    """Python's handler back, where :func:`quiet_interrupts` replaced it."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is _aborted:
        signal.signal(signal.SIGINT, signal.default_int_handler)


quiet_interrupts()
