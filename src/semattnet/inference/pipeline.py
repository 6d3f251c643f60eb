"""The one frame loop: frames from any :class:`~semattnet.data.frames.FrameSource`, through a completer,
into output sinks (:mod:`semattnet.inference.sinks`). What ``semattnet predict`` runs for folders, KITTI
splits and raw drives, bags and datasets, and what writes ``evaluate``'s predictions. For example::

    from semattnet.baselines import ClassicalCompleter
    from semattnet.data.sources import FolderSource
    from semattnet.inference.sinks import default_sinks

    source = FolderSource.pair("rgb/", "sparse/")
    plan = check_frames(source, default_sinks(), "out")    # every input decoded, every output checked
    run = plan.run(ClassicalCompleter())                   # (complete_frames does both)
    print(run.summary())                                   # "3 frame(s): 3 done"

What the run is told is typed (:mod:`~.options`): :class:`~.options.OutputSpec` (overwrite, resume) and
:class:`~.options.RunOptions` (``on_error``, read-ahead, real-time replay, batches).

A long run survives its bad frames and its kills:

* **Per-frame faults are the frame's.** A frame whose input cannot be read or completed (a corrupt file, a
  LiDAR scan with no point in the image, an empty sparse map: :func:`~.feed.is_frame_fault`) is skipped
  with one line naming it and why (``RunOptions(on_error="skip")``, the default for more than one frame), or
  stops the run with the frames done so far kept (``"stop"``). Errors of the run (a full disk, a sink that fails, a
  missing package) stop it at once.
* **Every frame's outputs appear as it is done**, each file atomically, and the frame is recorded in
  ``OUT/frames.json`` (:mod:`~.journal`) once they are all in place. With ``realtime`` or read-ahead the
  writing (every sink, the moves, the journal) runs a frame behind the network in a bounded background stage
  (:mod:`~.writer`; ``RunOptions.write_ahead``), in order, so the network is the only serial stage. A sink's
  fault on a frame (:func:`~.feed.is_frame_fault`) is that frame's, as a completer's is.
* **Ctrl-C and SIGTERM** stop the run once the frames handed to the writer are written and journaled (SIGTERM
  raises ``SystemExit(143)`` for it while the loop runs in the main thread).
* **Resume.** ``OutputSpec(resume=True)`` continues a killed or failed run in ``out``: the frames done, with every
  output whole, are kept; the rest are done; the run outputs (a bag, a recording, ``latency.json``) are
  written at the end over every frame, in order, so they equal those of an uninterrupted run.

The output policy (:mod:`semattnet._utils.outputs`): no output over or inside an input (the folder of
an input file counts), none existing unless ``overwrite`` (or ``resume``, in the run's own folder), every
input decoded: all before any work (:func:`check_frames`, which the CLI runs before it loads a model).
Under ``torchrun`` (same arguments on every rank) the frames are split over the processes and the files
are those of one process (:mod:`semattnet.inference.sharding`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from semattnet.data.frames import FrameSource
from semattnet.inference.completer import Completer
from semattnet.inference.loop import EXIT_DROPPED, EXIT_SKIPPED, FrameRun
from semattnet.inference.options import OutputSpec, RunOptions
from semattnet.inference.plan import RunPlan, check_frames
from semattnet.inference.sinks import Sink, write_prediction

__all__ = [
    "EXIT_DROPPED",
    "EXIT_SKIPPED",
    "Completer",
    "FrameRun",
    "OutputSpec",
    "RunOptions",
    "RunPlan",
    "check_frames",
    "complete_frames",
    "write_prediction",
]

PathLike = str | os.PathLike[str]


def complete_frames(
    source: FrameSource,
    completer: Completer,
    sinks: Sequence[Sink],
    out: PathLike,
    output: OutputSpec | None = None,
    options: RunOptions | None = None,
) -> FrameRun:
    """Complete every frame of ``source`` with ``completer`` and write what ``sinks`` say into ``out``:
    ``check_frames(source, sinks, out, output, options).run(completer)`` (:meth:`RunPlan.run` also takes the
    semantic maps, a timer and where the per-frame lines go).

    Each frame's files appear in ``out`` (atomically) as soon as it is completed and are recorded in
    ``out/frames.json`` (:mod:`~.journal`). A frame whose input cannot be read or completed (its fault:
    :func:`~.feed.is_frame_fault`) is skipped with one logged line (``on_error="skip"``, the default for more
    than one frame) or stops the run (``"stop"``), the frames done so far kept. Errors of the run (a full disk,
    a failing sink) stop it at once; the frames done stay, resumable. ``output``: the folder's rules (resume:
    keep the done frames; the run outputs then cover all); ``options``: on errors, read-ahead
    (:func:`~.feed.completions`), a real-time replay, batches (a :class:`~.completer.DepthCompleter`, through
    its input checks; the same results up to float rounding). :class:`~.sinks.RunSink` outputs (a bag, a
    recording, ``latency.json``) are put in place at the end.

    Returns:
        The :class:`FrameRun`: every frame's status, the depth PNGs of the frames done (all ranks).
    """
    return check_frames(source, sinks, out, output, options).run(completer)
