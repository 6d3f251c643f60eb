"""The one frame loop: frames from any :class:`~semattnet.data.frames.FrameSource`, through a completer,
into output sinks (:mod:`semattnet.inference.sinks`). What ``semattnet predict`` runs for folders and
KITTI raw drives, and what writes ``evaluate``'s predictions. For example::

    from semattnet.baselines import ClassicalCompleter
    from semattnet.data.sources import FolderSource
    from semattnet.inference.sinks import default_sinks

    source = FolderSource.pair("rgb/", "sparse/")
    check_frames(source, default_sinks(), "out")       # every input decoded, every output checked
    complete_frames(source, ClassicalCompleter(), default_sinks(), "out", checked=True)

The output policy (:mod:`semattnet._utils.outputs`): no output over or inside an input (the folder of
an input file counts), none existing unless ``overwrite``, every input decoded: all before any work
(:func:`check_frames`, which the CLI runs before it loads a model). Outputs are staged and appear only
when every frame succeeded. Under ``torchrun`` (same arguments on every rank) the frames are split over
the processes and the files are those of one process (:mod:`semattnet.inference.sharding`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from semattnet._utils.distributed import is_main
from semattnet._utils.outputs import OutputError, check_no_input_overlap, refuse_existing
from semattnet.data.frames import Frame, FrameSource
from semattnet.data.sources.semantic import SemanticMaps
from semattnet.inference.completer import Completion
from semattnet.inference.sharding import agree, on_main, process_group, rank_log, shard, shared_stage
from semattnet.inference.sinks import (
    DepthPngSink,
    LatencySink,
    Prediction,
    RunSink,
    Sink,
    output_files,
    predict_frame,
)
from semattnet.inference.stream import StageTimes, completions

__all__ = ["Completer", "check_frames", "complete_frames", "write_prediction"]

PathLike = str | os.PathLike[str]


class Completer(Protocol):
    """Anything called as ``completer(rgb, sparse, semantic)`` -> :class:`Completion`."""

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion: ...


def _check_outputs(source: FrameSource, sinks: Sequence[Sink], out: Path, overwrite: bool,
                   inputs: Sequence[PathLike | None]) -> None:  # fmt: skip
    """No output in or over an input, the output folder not the folder of an input file, none existing
    unless ``overwrite``."""
    runs = [s for s in sinks if isinstance(s, RunSink)]
    outputs = [out / p for p in output_files(source.names, sinks)] + [out / f for s in runs for f in s.files()]
    targets = [t for s in runs for t in s.targets()]
    given = [*source.inputs(), *(Path(p) for p in inputs if p is not None)]
    check_no_input_overlap(given, out_dir=out, out_files=[*outputs, *targets])
    if out.resolve() in {p.resolve().parent for p in given if p.is_file()}:
        raise OutputError(f"output folder {out} holds input files; choose an --out outside the inputs")
    _check_targets(targets, given, out)
    refuse_existing([*outputs, *targets], overwrite)


def _check_targets(targets: Sequence[Path], given: Sequence[Path], out: Path) -> None:
    """A run output (a bag, a recording) is not an input, nor inside an input folder, nor the output folder
    or one above it, and no two are the same path."""
    dirs = [p.resolve() for p in given if p.is_dir()]
    for t in targets:
        r = t.resolve()
        inside = next((d for d in dirs if r == d or r.is_relative_to(d)), None)
        if inside is not None:
            raise OutputError(f"output {t} is the input {inside} or inside it; choose a path outside the inputs")
        if out.resolve().is_relative_to(r):
            raise OutputError(f"output {t} would replace the output folder {out}; choose another path")
    if len({t.resolve() for t in targets}) < len(targets):
        raise OutputError(f"two outputs at one path ({', '.join(map(str, targets))}); choose distinct paths")


def check_frames(source: FrameSource, sinks: Sequence[Sink], out: PathLike, *, overwrite: bool = False,
                 inputs: Sequence[PathLike | None] = ()) -> None:  # fmt: skip
    """Every check before any work (and before a model is loaded): the outputs (rank 0), then every input
    of every frame decoded (each rank its share).

    ``inputs``: further paths the user gave (files or folders) that outputs must stay out of.

    Raises:
        FileExistsError: an output exists and ``overwrite`` is not set.
        OutputError: an output in or over an input.
        DataError: an input is missing or corrupt (naming the file).
    """
    with process_group():
        on_main(_check_outputs, source, sinks, Path(out), overwrite, inputs)
        agree(source.check, shard(source.names))


def write_prediction(stage: Path, frame: Frame, completion: Completion, sinks: Sequence[Sink]) -> Prediction:
    """The one writer: the hole / clamp rule and the quantisation once (:func:`~.sinks.predict_frame`),
    then every sink, into ``stage``."""
    pred = predict_frame(frame, completion)
    for sink in sinks:
        sink.write(stage, pred)
    return pred


def complete_frames(
    source: FrameSource,
    completer: Completer,
    sinks: Sequence[Sink],
    out: PathLike,
    *,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
    inputs: Sequence[PathLike | None] = (),
    semantic: SemanticMaps | None = None,
    checked: bool = False,
    timer: StageTimes | None = None,
    prefetch: int = 0,
) -> list[Path]:
    """Complete every frame of ``source`` with ``completer`` and write what ``sinks`` say into ``out``.

    ``semantic``: how frames without a semantic map get one (default: the fallback map for completers
    that need one). ``checked``: :func:`check_frames` already ran with these arguments (else it runs first).
    ``timer``: record per-stage times there (:class:`~.stream.StageTimes`; ``writing`` is every sink);
    ``prefetch`` > 0: read, project and segment that many frames ahead in a background thread
    (:func:`~.stream.completions`). :class:`~.sinks.RunSink` outputs (a bag, a recording) are opened
    before the first frame and put in place with the per-frame files, only when every frame succeeded.

    Returns:
        The depth PNGs (of the first :class:`~.sinks.DepthPngSink`) of every frame, all ranks.
    """
    out, timer = Path(out), timer if timer is not None else StageTimes()
    runs = [s for s in sinks if isinstance(s, RunSink)]
    with process_group():
        if not checked:
            check_frames(source, sinks, out, overwrite=overwrite, inputs=inputs)
        maps = agree((semantic or SemanticMaps()).bind, completer)
        maps.check_palette(completer, source)
        expected = output_files(source.names, sinks)
        depth_sink = next((s for s in sinks if isinstance(s, DepthPngSink)), None)
        log = rank_log(log)
        try:
            with shared_stage(out, overwrite, expected) as stage:
                for s in runs:
                    s.open(overwrite)
                for frame, completion in completions(source, completer, shard(source.names), maps, timer, prefetch):
                    with timer.time(frame.name, "writing"):
                        write_prediction(stage, frame, completion, sinks)
                    log(_line(frame, out, depth_sink))
                for s in runs:
                    if not isinstance(s, LatencySink) or is_main():  # one latency.json, rank 0's
                        s.finish(stage)
        except BaseException:
            for s in runs:
                s.abort()
            raise
        for s in runs:
            s.commit()
    return [out / p for name in source.names if depth_sink is not None and (p := depth_sink.path(name))]


def _line(frame: Frame, out: Path, depth_sink: Any) -> str:
    h, w = frame.size
    target = f" -> {out / depth_sink.path(frame.name)}" if depth_sink is not None else ""
    return f"{frame.name}: {np.count_nonzero(frame.sparse)} LiDAR pixels, {w}x{h}{target}"
