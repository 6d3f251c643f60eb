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
import re
from collections import Counter, deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.atomic import fsync_dir
from semattnet._utils.distributed import first_error, is_main, rank, world_size
from semattnet._utils.lock import FolderLock
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs, stage_folder
from semattnet.data.frames import Frame, FrameSource
from semattnet.data.io import encode_depth, read_depth
from semattnet.inference.completer import Completer, Completion
from semattnet.inference.contract import reading_only
from semattnet.inference.feed import FrameFault, check_inputs, completions, fault_reason, is_frame_fault, read_frame
from semattnet.inference.journal import FRAMES_FILE, FrameEntry, RunJournal, describe_counts
from semattnet.inference.options import OutputSpec, RunOptions
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sharding import agree, gather_rows, on_main, process_group, rank_log, shard
from semattnet.inference.sinks import Prediction, Sink, output_files, outputs_read, write_prediction
from semattnet.inference.stopping import terminate_as_exit
from semattnet.inference.timing import StageTimes
from semattnet.inference.writer import WriteStage

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


def _check_outputs(source: FrameSource, sinks: Sequence[Sink], out: Path, overwrite: bool,
                   inputs: Sequence[PathLike | None]) -> None:  # fmt: skip
    """The one output rule (:func:`~semattnet._utils.outputs.check_outputs`) over every output of the run: the
    folder, each frame's files and the run outputs (a bag, a recording), before the first frame."""
    names = [*output_files(source.names, sinks), *(f for s in sinks for f in s.files())]
    targets = [Output(s.option, t, s.kind) for s in sinks for t in s.targets()]
    given = [*source.inputs(), *(Path(p) for p in inputs if p is not None)]
    outputs = [Output("--out", out, "folder"), *(Output("--out", out / n) for n in names), *targets]
    check_outputs([("", p) for p in given], outputs, overwrite)
    check_no_input_overlap(given, out_files=[o.path for o in outputs[1:]])  # and hard links into input folders


@dataclass
class RunPlan:
    """What :func:`check_frames` decided for ``source`` into ``sinks`` and ``out``: the run's
    :class:`~.journal.RunJournal` (with the frames a resume keeps), the frames whose inputs failed the check
    (name -> reason; ``on_error="skip"``), ``on_error`` as it applies and the options; ``lock``: the output
    folder's lock, held from the check to the end of :meth:`run` (:meth:`release` it when the run does not
    happen)."""

    source: FrameSource
    sinks: Sequence[Sink]
    out: Path
    journal: RunJournal
    output: OutputSpec = field(default_factory=OutputSpec)
    options: RunOptions = field(default_factory=RunOptions)
    faults: dict[str, str] = field(default_factory=dict)
    on_error: str = "stop"
    lock: FolderLock | None = None

    @classmethod
    def trusted(cls, source: FrameSource, sinks: Sequence[Sink], out: PathLike,
                options: RunOptions | None = None) -> RunPlan:  # fmt: skip
        """A plan without the checks, for frames whose inputs and outputs the caller has checked (e.g. the
        thinned frames of a sparsity sweep, into a folder of its stage): nothing to skip or keep, no lock."""
        out, options = Path(out), options or RunOptions()
        journal = _journal(source, sinks, out, None, False)
        return cls(source, sinks, out, journal, OutputSpec(overwrite=True), options,
                   on_error=options.policy(len(source.names)))  # fmt: skip

    def run(self, completer: Completer, *, semantic: SemanticMaps | None = None, timer: StageTimes | None = None,
            log: Callable[[str], None] = print) -> FrameRun:  # fmt: skip
        """Complete the planned frames with ``completer`` (:func:`complete_frames` after the checks); the folder
        is released at the end, whatever happens.

        ``semantic``: how frames without a semantic map get one (default: the fallback map for completers that
        need one). ``timer``: per-stage times (:class:`~.timing.StageTimes`; ``writing`` is every sink).
        ``log``: where each frame's line goes."""
        try:
            timer = timer if timer is not None else StageTimes()
            return _execute(self, completer, semantic or SemanticMaps(), timer, log)
        finally:
            self.release()

    def release(self) -> None:
        """Let the output folder go (idempotent)."""
        if self.lock is not None:
            self.lock.release()


def check_frames(source: FrameSource, sinks: Sequence[Sink], out: PathLike, output: OutputSpec | None = None,
                 options: RunOptions | None = None) -> RunPlan:  # fmt: skip
    """Every check before any work (and before a model is loaded): a resume's journal, the outputs (rank 0),
    then every input of every frame to do decoded (each rank its share). Run it with :meth:`RunPlan.run`.

    ``output``: the folder's rules (:class:`~.options.OutputSpec`: overwrite, resume and the run's identity,
    further inputs that outputs must stay out of; default: nothing replaced). ``options``: how the frames are run
    (:class:`~.options.RunOptions`; ``on_error="stop"``: the first faulty input raises, ``"skip"``: faulty
    frames are noted and skipped).

    The output folder is locked (:class:`~semattnet._utils.lock.FolderLock`) first, until the end of
    :meth:`RunPlan.run` (or :meth:`RunPlan.release`).

    Raises:
        FileExistsError: an output exists and neither ``overwrite`` nor ``resume`` is set.
        OutputError: an output in or over an input; ``FolderBusyError``: another run is writing into ``out``.
        ResumeError: nothing to resume in ``out``, or a run with another identity.
        DataError: an input is missing or corrupt (naming the file), with ``on_error="stop"``.
    """
    out, lock = Path(out), FolderLock(out)
    with process_group():
        on_main(_acquire, lock)
        try:
            plan = _plan(source, sinks, out, output or OutputSpec(), options or RunOptions())
        except BaseException:
            lock.release()
            raise
    plan.lock = lock
    return plan


def _acquire(lock: FolderLock) -> None:
    lock.acquire()


def _plan(source: FrameSource, sinks: Sequence[Sink], out: Path, output: OutputSpec, options: RunOptions) -> RunPlan:
    """:func:`check_frames` once the folder is locked."""
    policy = options.policy(len(source.names))
    journal = agree(_journal, source, sinks, out, output.run, output.resume)
    if not (output.overwrite or output.resume):  # before the files it left are refused one by one: say --resume
        on_main(_refuse_earlier_run, out)
    on_main(_check_outputs, source, sinks, out, output.overwrite or output.resume, output.inputs)
    todo = [n for n in shard(source.names) if n not in journal.kept]
    faults = agree(check_inputs, source, todo, policy)
    position = {n: i for i, n in enumerate(source.names)}
    rows: list[FrameEntry] = [{"name": n, "status": "skipped", "reason": r} for n, r in faults.items()]
    bad = gather_rows(rows, key=lambda e: position[e["name"]])
    if bad and len(bad) == len(source.names):
        raise _nothing_done(bad)  # every input is bad: one line, before the model is loaded
    return RunPlan(source, sinks, out, journal, output, options, faults, policy)


def _journal(source: FrameSource, sinks: Sequence[Sink], out: Path, run: Mapping[str, object] | None,
             resume: bool) -> RunJournal:  # fmt: skip
    """This process's journal of the run (a resume keeps only frames that recorded this run's files)."""
    return RunJournal(out, source.names, run, resume, rank(), world_size(), lambda name: output_files([name], sinks))


def _refuse_earlier_run(out: Path) -> None:
    if (out / FRAMES_FILE).exists():
        raise FileExistsError(f"{out / FRAMES_FILE} exists: {out} holds an earlier run; pass --resume to continue "
                              "it or --overwrite to replace its outputs")  # fmt: skip


#: ``semattnet predict``'s exit status when some frames were skipped (their inputs could not be completed).
EXIT_SKIPPED = 3
#: ... when no frame was skipped but ``--realtime`` dropped some (the completer was slower than the sensor).
EXIT_DROPPED = 4


@dataclass
class FrameRun:
    """What :func:`complete_frames` did: ``journal`` (every frame's status; ``frames.json``) and ``paths``,
    the depth PNGs of the frames done (every rank's), in order."""

    journal: RunJournal
    paths: list[Path]

    @property
    def counts(self) -> dict[str, int]:
        return self.journal.counts()

    @property
    def exit_code(self) -> int:
        """0 when every frame was done, :data:`EXIT_SKIPPED` when some were skipped, else :data:`EXIT_DROPPED`
        when ``realtime`` dropped some."""
        c = self.counts
        return EXIT_SKIPPED if c["skipped"] else EXIT_DROPPED if c["dropped"] else 0

    def summary(self) -> str:
        """One line (and one per skipped frame's reason, grouped): what the run did."""
        lines = [f"{len(self.journal.names)} frame(s): {describe_counts(self.counts)}"]
        reasons = Counter(_kind(r) for _, r in self.journal.reasons("skipped"))
        lines += [f"  skipped x{n}: {why}" for why, n in reasons.most_common()]
        return "\n".join(lines)


def _kind(reason: str) -> str:
    """What a skip reason says is wrong, without where (its last clause, parenthesised details left out, so a
    colon inside them does not cut it): to group them."""
    return re.sub(r" \([^()]*\)", "", reason).rsplit(": ", 1)[-1]


class _FrameLoop:
    """One process's run: frames written into a hidden stage and moved into ``out`` one by one, each recorded
    in the journal once its files are in place; frames a resume keeps are replayed into the run outputs (a bag,
    a recording) in their place, so those cover every frame in order."""

    def __init__(self, source: FrameSource, sinks: Sequence[Sink], out: Path, plan: RunPlan, timer: StageTimes,
                 log: Callable[[str], None], semantic: SemanticMaps) -> None:  # fmt: skip
        self.source, self.out, self.plan, self.timer, self.log = source, out, plan, timer, log
        self.journal, self.semantic = plan.journal, semantic
        self.sinks = sinks
        self.files_first = sorted(sinks, key=lambda s: s.whole_run)  # the order frames are written in
        self.replays = [s for s in sinks if s.replays]
        self.depth_sink = next((s for s in sinks if s.role == "depth"), None)
        self.uncertainty_sink = next((s for s in sinks if s.role == "uncertainty"), None)
        self.names = shard(source.names)
        self.waiting = deque(n for n in self.names if n in self.journal.kept or n in plan.faults)
        self.position = {n: i for i, n in enumerate(self.names)}
        self.created = not out.exists()
        timer.wall_s += self.journal.earlier_wall_s  # the table covers the kept frames' time too
        stamps = source.info.stamps_ns  # the sensor period from every frame, not only those done
        if stamps is not None and len(stamps) == len(source.names):
            for name, ns in zip(source.names, stamps, strict=True):
                timer.stamp(name, int(ns) / 1e9)

    def todo(self) -> list[str]:
        return [n for n in self.names if n not in self.journal.kept and n not in self.plan.faults]

    def catch_up(self, name: str | None) -> None:
        """The kept and check-faulted frames before ``name`` (None: all that are left), in order."""
        last = len(self.names) if name is None else self.position[name]
        while self.waiting and self.position[self.waiting[0]] < last:
            other = self.waiting.popleft()
            if other in self.plan.faults:
                self.note(FrameFault(other, "skipped", self.plan.faults[other]))
            else:
                self.replay(other)

    def note(self, fault: FrameFault) -> None:
        """A frame not completed: journaled, one line."""
        self.catch_up(fault.name)
        self.journal.mark(fault.name, fault.status, fault.reason)
        self.journal.save(force=False)
        self.log(f"{fault.name}: {fault.status}: {fault.reason}")

    def replay(self, name: str) -> None:
        """A frame kept from an earlier run: its times into the table, its stored depth (and stored uncertainty,
        when the run writes it) into the run outputs."""
        for stage, ms in self.journal.frames[name].get("stage_ms", {}).items():
            self.timer.add(name, stage, ms / 1e3)
        if not self.replays or self.depth_sink is None:
            return
        frame = read_frame(self.source, name, self.semantic, StageTimes())
        stored = read_depth(self.journal.stored(name, str(self.depth_sink.path(name))))  # never a link's target
        pred = Prediction(frame, Completion(stored), stored, encode_depth(stored), stored)
        if self.uncertainty_sink is not None:
            pred.uncertainty = read_depth(self.journal.stored(name, str(self.uncertainty_sink.path(name))))
            pred.uncertainty_png = encode_depth(pred.uncertainty)
        for sink in self.replays:
            sink.write(self.out, pred)

    def write(self, stage: Path, frame: Frame, completion: Completion) -> None:
        """A completed frame: every sink, the frame's files moved into place, then journaled. A sink's fault on
        the frame (:func:`~.feed.is_frame_fault`) is the frame's: its staged files removed, noted ``skipped``, or
        ``failed`` and raised with ``on_error="stop"``."""
        self.catch_up(frame.name)
        try:
            files = self._put(stage, frame, completion)
        except Exception as exc:
            if not is_frame_fault(exc):
                raise
            for rel in output_files([frame.name], self.sinks):
                (stage / rel).unlink(missing_ok=True)
            self.timer.discard(frame.name)
            stop = self.plan.on_error == "stop"
            self.note(FrameFault(frame.name, "failed" if stop else "skipped", fault_reason(exc)))
            if stop:
                raise
            return
        stage_ms = {k: 1e3 * v for k, v in self.timer.times[frame.name].items()}
        self.journal.done(frame.name, files, stage_ms, inputs=frame.paths.values())
        self.journal.save(force=False)
        self.log(_line(frame, self.out, self.depth_sink))

    def _put(self, stage: Path, frame: Frame, completion: Completion) -> list[str]:
        """Every sink (the frame's files first, then the run outputs, so a file's fault leaves those without
        the frame), the frame's files moved from ``stage`` into place; timed as ``writing``. Returns the files."""
        with self.timer.time(frame.name, "writing"):
            stage_ms = {k: 1e3 * v for k, v in self.timer.times.get(frame.name, {}).items()}
            write_prediction(stage, frame, completion, self.files_first, stage_ms, self.plan.options.png_level())
            files = output_files([frame.name], self.sinks)
            for rel in files:
                (self.out / rel).parent.mkdir(parents=True, exist_ok=True)
                os.replace(stage / rel, self.out / rel)
            fsync_dir(self.out)
        return files

    def finish(self, stage: Path) -> None:
        """Every frame seen: the run outputs completed (rank 0's ``latency.json``) and moved into place, when a
        frame is done."""
        self.catch_up(None)
        self.timer.not_done = {k: v for k, v in self.journal.counts().items() if k in ("skipped", "dropped")}
        for s in self.sinks:
            if not s.once or is_main():
                s.finish(stage)
        if world_size() == 1 and not self.journal.counts()["done"]:
            return  # no frame done: nothing is put in place (no latency.json; the run raises in _close)
        for rel in [f for s in self.sinks for f in s.files()] if is_main() else []:
            if (stage / rel).is_file():
                os.replace(stage / rel, self.out / rel)

    def forget(self) -> None:
        """After a run error: keep the journal when a frame is done, else leave no trace of this run (the journal
        it found, an earlier run's, put back)."""
        if self.journal.counts()["done"]:
            try:
                self.journal.save()
            except OSError:  # a full disk: the journal keeps its last save (those frames are redone on resume)
                pass
            return
        self.journal.restore()
        if self.created and self.out.is_dir() and not any(self.out.iterdir()):
            self.out.rmdir()


def _run_frames(loop: _FrameLoop, completer: Completer) -> None:
    """The frames of this process through the completer into ``loop`` (the run outputs opened before and
    finished after; aborted on any error)."""
    plan, options, timer = loop.plan, loop.plan.options, loop.timer
    depth = options.write_depth()
    if depth:
        timer.beside["writing"] = "the writer thread"
    try:  # each frame is written into the stage, then moved into place; the writing `depth` frames behind
        with stage_folder(loop.out) as stage, WriteStage(depth) as writer:
            for s in loop.sinks:
                s.open(plan.output.overwrite or plan.output.resume)

            def note(fault: FrameFault) -> None:
                writer.submit(partial(loop.note, fault), frame=False)

            for frame, completion in completions(loop.source, completer, loop.todo(), loop.semantic, timer,
                                                 options.prefetch, report=note, realtime=options.realtime,
                                                 batch_size=options.batch_size,
                                                 stop_on_fault=plan.on_error == "stop"):  # fmt: skip
                writer.submit(partial(loop.write, stage, frame, completion))
            timer.begin()  # the writing of the last frames counts in the wall time
            try:
                writer.drain()
            finally:
                timer.end()
            timer.write_waited_s = writer.waited_s
            loop.finish(stage)
    except BaseException:
        for s in loop.sinks:
            s.abort()
        raise


def complete_frames(source: FrameSource, completer: Completer, sinks: Sequence[Sink], out: PathLike,
                    output: OutputSpec | None = None, options: RunOptions | None = None) -> FrameRun:  # fmt: skip
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


def _execute(plan: RunPlan, completer: Completer, semantic: SemanticMaps, timer: StageTimes,
             log: Callable[[str], None]) -> FrameRun:  # fmt: skip
    """:meth:`RunPlan.run`: the loop of every process, the first error of any raised on all."""
    with process_group():
        maps = agree(semantic.bind, completer)
        maps.check_palette(completer, plan.source)
        loop = _FrameLoop(plan.source, plan.sinks, plan.out, plan, timer, rank_log(log), maps)
        first = first_error(_attempt_run(loop, completer))
        if first is not None:
            raise first
        return _close(loop)


def _attempt_run(loop: _FrameLoop, completer: Completer) -> Exception | None:
    """:func:`_run_frames`, its error returned (for every rank to agree on); on any error the frames done
    stay journaled. Ctrl-C and SIGTERM are raised (once the frames handed to the writer are written)."""
    try:
        with terminate_as_exit(), reading_only(completer, outputs_read(loop.sinks)):
            _run_frames(loop, completer)
    except BaseException as exc:
        loop.forget()
        if not isinstance(exc, Exception):
            raise
        return exc
    return None


def _nothing_done(entries: Sequence[FrameEntry]) -> DataError:
    """The run's error when none of ``entries`` (every frame's) could be completed: nothing to keep."""
    bad = [e for e in entries if e["status"] != "pending"]
    counts = describe_counts(Counter(e["status"] for e in entries))
    first = f"; the first: {bad[0]['name']}: {bad[0].get('reason', '')}" if bad else ""
    return DataError(f"no frame could be completed ({counts}){first}")


def _close(loop: _FrameLoop) -> FrameRun:
    """The run outputs put in place and the journal complete (every process's entries, in ``frames.json``);
    a run in which no frame could be completed leaves nothing and raises instead."""
    journal, names = loop.journal, loop.source.names
    position = {n: i for i, n in enumerate(names)}
    entries = gather_rows([journal.frames[n] for n in loop.names], key=lambda e: position[e["name"]])
    if entries and not any(e["status"] == "done" for e in entries):
        for s in loop.sinks:
            s.abort()
        loop.forget()
        raise _nothing_done(entries)
    try:
        for s in loop.sinks:
            s.commit()
        wall = loop.timer.wall_s - journal.earlier_wall_s  # this run's share
        if world_size() == 1:
            journal.save(complete=True, wall_s=wall)
        elif is_main():
            journal.merge(entries, complete=True, wall_s=wall)
    finally:  # a live server stops only now: frames.json is complete whatever its clients do
        for s in loop.sinks:
            s.close()
    for e in entries:
        journal.frames[e["name"]] = e
    depth = loop.depth_sink
    paths = [loop.out / p for e in entries if e["status"] == "done" and depth and (p := depth.path(e["name"]))]
    return FrameRun(journal, paths)


def _line(frame: Frame, out: Path, depth_sink: Sink | None) -> str:
    h, w = frame.size
    rel = depth_sink.path(frame.name) if depth_sink is not None else None
    target = f" -> {out / rel}" if rel is not None else ""
    return f"{frame.name}: {np.count_nonzero(frame.sparse)} LiDAR pixels, {w}x{h}{target}"
