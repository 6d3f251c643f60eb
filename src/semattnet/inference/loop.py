"""The one frame loop: the frames a :class:`~.plan.RunPlan` left to do, through a completer, into the output
sinks, each frame's files moved into ``out`` and journaled as it is done (:mod:`~.pipeline` tells the whole
story: faults, kills, resume)."""

from __future__ import annotations

import os
import re
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Protocol

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.atomic import fsync_dir
from semattnet._utils.distributed import first_error, is_main, world_size
from semattnet._utils.outputs import stage_folder
from semattnet.data.frames import Frame, FrameSource
from semattnet.data.io import encode_depth
from semattnet.inference.completer import Completer, Completion
from semattnet.inference.contract import reading_only
from semattnet.inference.feed import FrameFault, completions, fault_reason, is_frame_fault, read_frame
from semattnet.inference.journal import FrameEntry, RunJournal, describe_counts
from semattnet.inference.options import OutputSpec, RunOptions
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sharding import agree, gather_rows, process_group, rank_log, shard
from semattnet.inference.sinks import Prediction, Sink, output_files, outputs_read, write_prediction
from semattnet.inference.stopping import terminate_as_exit
from semattnet.inference.timing import StageTimes
from semattnet.inference.writer import WriteStage

__all__ = ["EXIT_DROPPED", "EXIT_SKIPPED", "FrameRun", "PlannedRun", "execute", "nothing_done"]


class PlannedRun(Protocol):
    """What the loop reads of a plan (:class:`~.plan.RunPlan`): the frames, the sinks and the folder, the journal
    (with the frames a resume keeps), the frames whose inputs failed the check, the fault policy, the options."""

    source: FrameSource
    sinks: Sequence[Sink]
    out: Path
    journal: RunJournal
    output: OutputSpec
    options: RunOptions
    faults: dict[str, str]
    on_error: str


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
        """One line, and one per kind of skip reason naming its frames: what the run did."""
        lines = [f"{len(self.journal.names)} frame(s): {describe_counts(self.counts)}"]
        groups: dict[str, list[str]] = {}
        for name, reason in self.journal.reasons("skipped"):
            groups.setdefault(_kind(reason), []).append(name)
        by_count = sorted(groups.items(), key=lambda kind: -len(kind[1]))  # stable: ties in the frames' order
        lines += [f"  skipped x{len(names)}: {why}: {_some(names)}" for why, names in by_count]
        return "\n".join(lines)


def _kind(reason: str) -> str:
    """What a skip reason says is wrong, without where (its last clause, parenthesised details left out, nested
    ones too, so that a colon inside them does not cut it): to group them."""
    while (shorter := re.sub(r" ?\([^()]*\)", "", reason)) != reason:
        reason = shorter
    return reason.rsplit(": ", 1)[-1]


def _some(names: list[str], most: int = 5) -> str:
    """``names`` joined, the first ``most`` of them and how many more."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


class _FrameLoop:
    """One process's run: frames written into a hidden stage and moved into ``out`` one by one, each recorded
    in the journal once its files are in place; frames a resume keeps are replayed into the run outputs (a bag,
    a recording) in their place, so those cover every frame in order."""

    def __init__(
        self,
        source: FrameSource,
        sinks: Sequence[Sink],
        out: Path,
        plan: PlannedRun,
        timer: StageTimes,
        log: Callable[[str], None],
        semantic: SemanticMaps,
    ) -> None:
        self.source = source
        self.out = out
        self.plan = plan
        self.timer = timer
        self.log = log
        self.journal = plan.journal
        self.semantic = semantic
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
        stored = self.journal.stored_depth(name, str(self.depth_sink.path(name)))  # never a link's target
        pred = Prediction(frame, Completion(stored), stored, encode_depth(stored), stored)
        if self.uncertainty_sink is not None:
            pred.uncertainty = self.journal.stored_depth(name, str(self.uncertainty_sink.path(name)))
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


def _frames_into_sinks(loop: _FrameLoop, completer: Completer) -> None:
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

            for frame, completion in completions(
                loop.source,
                completer,
                loop.todo(),
                loop.semantic,
                timer,
                options.prefetch,
                report=note,
                realtime=options.realtime,
                batch_size=options.batch_size,
                stop_on_fault=plan.on_error == "stop",
            ):
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


def execute(
    plan: PlannedRun, completer: Completer, semantic: SemanticMaps, timer: StageTimes, log: Callable[[str], None]
) -> FrameRun:
    """the loop of :meth:`~.plan.RunPlan.run`: the loop of every process, the first error of any raised on all."""
    with process_group():
        maps = agree(semantic.bind, completer)
        maps.check_palette(completer, plan.source)
        loop = _FrameLoop(plan.source, plan.sinks, plan.out, plan, timer, rank_log(log), maps)
        first = first_error(_attempt_run(loop, completer))
        if first is not None:
            raise first
        return _close(loop)


def _attempt_run(loop: _FrameLoop, completer: Completer) -> Exception | None:
    """:func:`_frames_into_sinks`, its error returned (for every rank to agree on); on any error the frames done
    stay journaled. Ctrl-C and SIGTERM are raised (once the frames handed to the writer are written)."""
    try:
        with terminate_as_exit(), reading_only(completer, outputs_read(loop.sinks)):
            _frames_into_sinks(loop, completer)
    except BaseException as exc:
        loop.forget()
        if not isinstance(exc, Exception):
            raise
        return exc
    return None


def nothing_done(entries: Sequence[FrameEntry]) -> DataError:
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
        raise nothing_done(entries)
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
