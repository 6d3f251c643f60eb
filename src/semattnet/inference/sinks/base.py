"""What every output sink is (:class:`Sink`, :class:`RunSink`), the sink registry (:data:`SINKS`), how ``predict``
makes sinks from its options (:class:`SinkOptions`, :class:`OutputSettings`) and the one writer of a frame
(:func:`write_prediction`)."""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from semattnet._utils.registry import ClassRegistry
from semattnet.inference.prediction import Prediction, predict_frame
from semattnet.inference.uncertainty import UncertaintyLimit

if TYPE_CHECKING:  # the stage times are imported where used
    from semattnet.data.frames import Frame
    from semattnet.inference.contract import Completion
    from semattnet.inference.timing import StageTimes

__all__ = [
    "SINKS",
    "OutputSettings",
    "RunSink",
    "Sink",
    "SinkOptions",
    "list_sinks",
    "output_files",
    "outputs_read",
    "register_sink",
    "write_prediction",
]


@dataclass
class Sink:
    """Writes ``FOLDER/NAME+SUFFIX`` per frame (``rename``: frame name -> file name instead; ``only``:
    the frames it writes, default all). Subclasses write the file in :meth:`save`.

    What the frame loop asks of every sink (a per-frame sink's run hooks do nothing; :class:`RunSink`'s do):
    :meth:`open` before the first frame, :meth:`write` per frame, :meth:`finish`, then :meth:`commit` or
    :meth:`abort`, and :meth:`close` once ``frames.json`` records the run; ``files()`` and ``targets()``, its
    outputs of the whole run. Its facts: ``role``, what the
    loop finds it by (``depth``: the depth PNG, named in each frame's line, the paths a run returns and read
    back by a resume; ``uncertainty``: the uncertainty PNG a resume reads back); ``replays``: a resumed run hands
    it the frames kept from the earlier run; ``once``: under ``torchrun`` one process (rank 0) finishes it;
    ``whole_run``: it writes one output for the whole run (a :class:`RunSink`), fed each frame after the frame's
    files are written, so a file's fault on a frame leaves it without that frame."""

    suffix: str = ".png"
    folder: str = ""
    only: Collection[str] | None = None
    rename: Mapping[str, str] | None = None
    role: ClassVar[str] = ""
    replays: ClassVar[bool] = False
    once: ClassVar[bool] = False
    whole_run: ClassVar[bool] = False
    #: The option that names ``targets()`` and what they are (a kind of :data:`semattnet._utils.outputs.KINDS`).
    option: ClassVar[str] = "--out"
    kind: ClassVar[str] = "file"

    def reads(self) -> frozenset[str] | None:
        """The outputs of the completion it reads: fields of :class:`~semattnet.models.outputs.DepthCompletionOutput`
        (:data:`~semattnet.models.outputs.DEPTH_OUTPUTS` for the final depth, ``uncertainty`` for the uncertainty),
        None for all of them (the default: a sink that does not say gets everything). The frame loop computes the
        union over its sinks only (:func:`outputs_read`)."""
        return None

    def path(self, name: str) -> str | None:
        """The file for frame ``name``, relative to the output folder (None: not written)."""
        if self.only is not None and name not in self.only:
            return None
        file = self.rename[name] if self.rename is not None else f"{name}{self.suffix}"
        return f"{self.folder}/{file}" if self.folder else file

    def write(self, stage: Path, pred: Prediction) -> None:
        rel = self.path(pred.frame.name)
        if rel is not None:
            (stage / rel).parent.mkdir(parents=True, exist_ok=True)
            self.save(stage / rel, pred)

    def save(self, path: Path, pred: Prediction) -> None:
        raise NotImplementedError

    def files(self) -> list[str]:
        """Its outputs of the whole run inside the output folder (written into the stage by :meth:`finish`)."""
        return []

    def targets(self) -> list[Path]:
        """Its outputs of the whole run elsewhere (checked like every output)."""
        return []

    def open(self, overwrite: bool = False) -> None:
        """Start the run (``overwrite``: existing targets may be replaced at :meth:`commit`)."""

    def finish(self, stage: Path) -> None:
        """Every frame written: complete the run's outputs (``files()`` into ``stage``, ``targets()`` staged)."""

    def commit(self) -> None:
        """Move ``targets()`` into place."""

    def abort(self) -> None:
        """Remove whatever was staged."""

    def close(self) -> None:
        """The run is recorded: stop what still serves (nothing for a file)."""


#: Sink name -> :class:`~semattnet._utils.registry.Entry` (the class and the ``predict`` option asking for it).
#: The robot sinks enrol themselves when :mod:`semattnet.robotics` is imported (which imports this layer, never
#: the reverse; ``import semattnet`` does). Every registered sink runs through the suite in
#: ``tests/registry/test_sinks.py``.
SINKS: ClassRegistry[Sink] = ClassRegistry(
    "sink", homes=("semattnet.inference.sinks.files", "semattnet.inference.sinks.latency")
)


def register_sink(
    name: str, option: str | None = None, options: type[SinkOptions] | None = None
) -> Callable[[type[Sink]], type[Sink]]:
    """Enrol a :class:`Sink` subclass as ``name`` (``option``: the CLI option asking for it; ``options``: how
    ``predict`` makes it, with its own command-line options: :class:`SinkOptions`)."""
    return SINKS.register(name, option, options)


@dataclass(frozen=True)
class OutputSettings:
    """What the sinks of one run share (``predict``'s output options): ``npy``, ``uncertainty``, the clouds'
    ``max_depth`` / ``top_crop`` / ``max_uncertainty``, the run's ``timer`` and where messages go (``log``)."""

    npy: bool = False
    uncertainty: bool = False
    max_uncertainty: UncertaintyLimit | None = None
    max_depth: float = 80.0
    top_crop: int = 0
    timer: StageTimes | None = None
    log: Callable[[str], None] = print


@dataclass(frozen=True)
class SinkOptions:
    """How ``predict`` makes a sink: its own command-line options (the fields, with
    :func:`~semattnet._utils.registry.option` metadata, listed under "Outputs") and :meth:`sinks`.

    Facts (class attributes) the output rules read: ``needs_recording``: its output needs a recording of a
    camera and a LiDAR (``--ply``); ``needs_intrinsics``: it needs the camera's intrinsics from the input (the
    robot outputs); ``clouds``: it draws point clouds (``--max-uncertainty`` applies): ``always``, ``recording``
    (only for a recording's frames) or ``""``. Whether a resumed run rebuilds it from the kept frames is the
    sink's own :attr:`RunSink.replays`."""

    needs_recording: ClassVar[bool] = False
    needs_intrinsics: ClassVar[bool] = False
    clouds: ClassVar[str] = ""

    def asked(self) -> bool:
        """Whether its options ask for it (any given)."""
        return any(self.__dict__[f.name] not in (None, False) for f in fields(self))

    def sinks(self, settings: OutputSettings) -> list[Sink]:
        """The sinks to write (none when not asked)."""
        raise NotImplementedError  # every entry's options define it


def list_sinks() -> list[str]:
    """The registered sink names."""
    return SINKS.names()


class RunSink(Sink):
    """A sink with one output for the whole run, around the frame loop of
    :func:`~semattnet.inference.pipeline.complete_frames`: :meth:`open` before the first frame, :meth:`write`
    per frame, :meth:`finish` after the last one (the output complete, still staged), then :meth:`commit`
    once the per-frame files are in place, or :meth:`abort` (nothing left) on any error; :meth:`close` last,
    once ``frames.json`` records the run complete (a server stops there, so no client can delay the record).

    ``files()``: its outputs inside the output folder (written into the stage by :meth:`finish`);
    ``targets()``: its outputs elsewhere (checked like every output: never over or inside an input, none
    existing unless ``overwrite``). ``replays``: whether a resumed run hands it the frames kept from the
    earlier run (their stored depth, in their place), so that its output covers every frame."""

    replays: ClassVar[bool] = True
    whole_run: ClassVar[bool] = True

    def path(self, name: str) -> str | None:
        return None

    def write(self, stage: Path, pred: Prediction) -> None:
        """One frame."""


def outputs_read(sinks: Sequence[Sink]) -> frozenset[str] | None:
    """The outputs of the completion that any of ``sinks`` reads (:meth:`Sink.reads`): what a run computes
    (None: all, when one of them reads all)."""
    read: frozenset[str] = frozenset()
    for sink in sinks:
        more = sink.reads()
        if more is None:
            return None
        read |= more
    return read


def output_files(names: Sequence[str], sinks: Sequence[Sink]) -> list[str]:
    """Every file the sinks write for ``names``, relative to the output folder, frame by frame."""
    return [p for name in names for sink in sinks if (p := sink.path(name)) is not None]


def write_prediction(
    stage: Path,
    frame: Frame,
    completion: Completion,
    sinks: Sequence[Sink],
    stage_ms: Mapping[str, float] | None = None,
    compress_level: int | None = None,
) -> Prediction:
    """The one writer: the hole / clamp rule and the quantisation once
    (:func:`~semattnet.inference.prediction.predict_frame`), then every sink, into ``stage``. ``stage_ms``: the
    frame's stage times so far (for the live view); ``compress_level``: the PNGs' zlib level (None:
    :data:`~semattnet.data.io.PNG_COMPRESS_LEVEL`)."""
    pred = predict_frame(frame, completion)
    pred.stage_ms = dict(stage_ms or {})
    if compress_level is not None:
        pred.compress_level = compress_level
    for sink in sinks:
        sink.write(stage, pred)
    return pred
