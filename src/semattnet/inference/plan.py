"""The plan of a run (:func:`check_frames`): every check before any work and before a model is loaded. The
output folder locked, a resume's journal read, every output checked against the output rule, every input of
every frame decoded; what it decides is a :class:`RunPlan`, which :meth:`RunPlan.run` hands to the frame loop
(:mod:`~.loop`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from semattnet._errors import DataError
from semattnet._utils.distributed import rank, world_size
from semattnet._utils.lock import FolderLock
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs
from semattnet.data.frames import FrameSource
from semattnet.inference.completer import Completer
from semattnet.inference.feed import is_frame_fault
from semattnet.inference.journal import FRAMES_FILE, FrameEntry, RunJournal
from semattnet.inference.loop import FrameRun, execute, nothing_done
from semattnet.inference.options import OutputSpec, RunOptions
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sharding import agree, gather_rows, on_main, process_group, shard
from semattnet.inference.sinks import Sink, output_files
from semattnet.inference.timing import StageTimes

__all__ = ["RunPlan", "check_frame_inputs", "check_frames"]

PathLike = str | os.PathLike[str]


def _check_outputs(
    source: FrameSource, sinks: Sequence[Sink], out: Path, overwrite: bool, inputs: Sequence[PathLike | None]
) -> None:
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
    def trusted(
        cls, source: FrameSource, sinks: Sequence[Sink], out: PathLike, options: RunOptions | None = None
    ) -> RunPlan:
        """A plan without the checks, for frames whose inputs and outputs the caller has checked (e.g. the
        thinned frames of a sparsity sweep, into a folder of its stage): nothing to skip or keep, no lock."""
        out, options = Path(out), options or RunOptions()
        journal = _journal(source, sinks, out, None, False, options.realtime is not None)
        return cls(
            source, sinks, out, journal, OutputSpec(overwrite=True), options, on_error=options.policy(len(source.names))
        )

    def run(
        self,
        completer: Completer,
        *,
        semantic: SemanticMaps | None = None,
        timer: StageTimes | None = None,
        log: Callable[[str], None] = print,
    ) -> FrameRun:
        """Complete the planned frames with ``completer`` (:func:`complete_frames` after the checks); the folder
        is released at the end, whatever happens.

        ``semantic``: how frames without a semantic map get one (default: the fallback map for completers that
        need one). ``timer``: per-stage times (:class:`~.timing.StageTimes`; ``writing`` is every sink).
        ``log``: where each frame's line goes."""
        try:
            timer = timer if timer is not None else StageTimes()
            return execute(self, completer, semantic or SemanticMaps(), timer, log)
        finally:
            self.release()

    def release(self) -> None:
        """Let the output folder go (idempotent)."""
        if self.lock is not None:
            self.lock.release()


def check_frames(
    source: FrameSource,
    sinks: Sequence[Sink],
    out: PathLike,
    output: OutputSpec | None = None,
    options: RunOptions | None = None,
) -> RunPlan:
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


#: Faulty frames named in full in the one line that stops an ``on_error="stop"`` run; the rest counted.
LISTED_FAULTS = 5


def check_frame_inputs(source: FrameSource, names: Sequence[str], on_error: str) -> dict[str, str]:
    """Decode the inputs of ``names``: ``skip`` returns every faulty frame's reason (frame by frame, in order);
    ``stop`` raises: the one fault as it is, or one line naming every faulty frame (the first
    :data:`LISTED_FAULTS`, the rest counted), so that one check tells what to repair."""
    faults: dict[str, str] = {}
    first: Exception | None = None
    for name in names:
        try:
            source.check([name])
        except Exception as exc:
            if not is_frame_fault(exc):
                raise
            first = first or exc
            faults[name] = " ".join(str(exc).split())
    if on_error != "stop" or first is None:
        return faults
    if len(faults) == 1:
        raise first
    shown = "; ".join(list(faults.values())[:LISTED_FAULTS])
    more = f"; and {len(faults) - LISTED_FAULTS} more" if len(faults) > LISTED_FAULTS else ""
    raise DataError(f"{len(faults)} of {len(names)} frames cannot be read: {shown}{more}") from first


def _plan(source: FrameSource, sinks: Sequence[Sink], out: Path, output: OutputSpec, options: RunOptions) -> RunPlan:
    """:func:`check_frames` once the folder is locked."""
    policy = options.policy(len(source.names))
    journal = agree(_journal, source, sinks, out, output.run, output.resume, options.realtime is not None)
    if not (output.overwrite or output.resume):  # before the files it left are refused one by one: say --resume
        on_main(_refuse_earlier_run, out)
    on_main(_check_outputs, source, sinks, out, output.overwrite or output.resume, output.inputs)
    todo = [n for n in shard(source.names) if n not in journal.kept]
    faults = agree(check_frame_inputs, source, todo, policy)
    position = {n: i for i, n in enumerate(source.names)}
    rows: list[FrameEntry] = [{"name": n, "status": "skipped", "reason": r} for n, r in faults.items()]
    bad = gather_rows(rows, key=lambda e: position[e["name"]])
    if bad and len(bad) == len(source.names):
        raise nothing_done(bad)  # every input is bad: one line, before the model is loaded
    return RunPlan(source, sinks, out, journal, output, options, faults, policy)


def _journal(
    source: FrameSource,
    sinks: Sequence[Sink],
    out: Path,
    run: Mapping[str, object] | None,
    resume: bool,
    paced: bool,
) -> RunJournal:
    """This process's journal of the run (a resume keeps only frames that recorded this run's files; ``paced``: a
    real-time run, saved at intervals)."""
    return RunJournal(
        out, source.names, run, resume, rank(), world_size(), lambda name: output_files([name], sinks), paced
    )


def _refuse_earlier_run(out: Path) -> None:
    if (out / FRAMES_FILE).exists():
        raise FileExistsError(
            f"{out / FRAMES_FILE} exists: {out} holds an earlier run; pass --resume to continue "
            "it or --overwrite to replace its outputs"
        )
