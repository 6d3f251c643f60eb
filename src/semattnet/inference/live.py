"""The one frame loop for frames a sensor pushes (a live node): the frames of a
:class:`~semattnet.data.frames.LiveSource` through a completer into run sinks, with the loop's fault rule, stage
times and the whole sink lifecycle, and nothing written into a folder.

What it shares with :mod:`~.loop` (the loop of recordings and folders): the completion
(:func:`~.feed.live_completions`, the live reader of :func:`~.feed.completions`), the fault rule (a frame's own
fault, :func:`~.feed.is_frame_fault`, is that frame's: one line, and the loop goes on; any other error ends the
run), the stage times (:class:`~.timing.StageTimes`, each frame then settled into a
:class:`~.timing.StageTally`, so memory stays constant however long the node runs) and the sinks' lifecycle:
``open`` before the first frame, ``write`` per frame (:func:`~.sinks.write_prediction`, timed as ``writing``),
``finish`` and ``commit`` at the end or ``abort`` on an error, and ``close`` always (a viewer's server stops
there). What it does not have: names known ahead, a journal, an output folder, resume.
"""

from __future__ import annotations

import threading
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from semattnet.data.frames import Frame, LiveSource
from semattnet.inference.contract import Completer, Completion
from semattnet.inference.feed import FrameFault, fault_reason, is_frame_fault, live_completions
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sinks import Sink, write_prediction
from semattnet.inference.timing import StageTally, StageTimes

__all__ = ["LiveRun", "run_live"]

_R = TypeVar("_R")


@dataclass
class LiveRun:
    """What a live run did so far, by status (``done``, ``skipped``, ``dropped``), and its stage times: per frame
    while it is in the loop (``timer``), then in ``tally`` (constant memory)."""

    done: int = 0
    skipped: int = 0
    dropped: int = 0
    timer: StageTimes = field(default_factory=StageTimes)
    tally: StageTally = field(default_factory=StageTally)

    def count(self, fault: FrameFault) -> None:
        """A frame not completed, counted by its status (``failed`` counts as ``skipped``)."""
        if fault.status == "dropped":
            self.dropped += 1
        else:
            self.skipped += 1
            self.timer.settle(fault.name)  # forgotten: its times and stamp (a frame not completed is not tallied)


def run_live(
    source: LiveSource[_R],
    completer: Completer,
    sinks: Sequence[Sink],
    stop: threading.Event,
    run: LiveRun | None = None,
    *,
    semantic: SemanticMaps | None = None,
    frames: int | None = None,
    report: Callable[[FrameFault], None] | None = None,
    tick: Callable[[], None] | None = None,
) -> LiveRun:
    """Complete what ``source`` pushes into ``sinks`` until ``stop`` is set (or ``frames`` frames were done or
    skipped): the module doc. ``run``: the counts and times to go on from (a node spun more than once); ``report``:
    each frame not completed (``skipped`` with its reason, ``dropped``); ``tick``: runs between frames."""
    run = run if run is not None else LiveRun()

    def note(fault: FrameFault) -> None:
        run.count(fault)
        if report is not None:
            report(fault)

    for sink in sinks:
        sink.open()
    try:
        completed = live_completions(
            source, completer, stop, run.timer, semantic=semantic, report=note, frames=frames, tick=tick
        )
        for frame, completion in completed:
            try:
                _write(frame, completion, sinks, run.timer)
            except Exception as exc:
                if not is_frame_fault(exc):
                    raise
                note(FrameFault(frame.name, "skipped", fault_reason(exc)))
                continue
            run.done += 1
            run.tally.add(run.timer.settle(frame.name))
        for sink in sinks:
            sink.finish(Path("."))
        for sink in sinks:
            sink.commit()
    except BaseException:
        for sink in sinks:
            sink.abort()
        raise
    finally:
        for sink in sinks:
            sink.close()
    return run


def _write(frame: Frame, completion: Completion, sinks: Sequence[Sink], timer: StageTimes) -> None:
    """Every sink gets the frame (timed as ``writing``); nothing is written into a folder (run sinks only)."""
    stage_ms = {k: 1e3 * v for k, v in timer.times.get(frame.name, {}).items()}
    with timer.time(frame.name, "writing"), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # holes are NaN on the wire: the PNG's note is not for a node
        write_prediction(Path("."), frame, completion, sinks, stage_ms)
