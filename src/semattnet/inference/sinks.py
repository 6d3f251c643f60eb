"""Output sinks: what :func:`semattnet.inference.pipeline.complete_frames` writes per frame.

Every sink receives a :class:`Prediction`: the :class:`~semattnet.data.frames.Frame`, the typed
:class:`~semattnet.inference.completer.Completion` (with its
:class:`~semattnet.models.outputs.DepthCompletionOutput`) and the depth after the one hole / clamp rule
(:func:`semattnet.data.io.clamp_for_png`, applied once per frame) and the one quantisation
(:func:`semattnet.data.io.encode_depth`, once per frame). The PLY and the panel use the depth exactly as
the PNG stores it; the ``.npy`` holds the clamped depth at full float precision.

Files per frame ``NAME`` (names as ``semattnet predict`` has always written them): ``NAME.png`` (KITTI
16-bit depth), ``NAME_color.png``, ``NAME.npy`` (float32 metres), ``NAME.ply`` (back-projected, with the
fusion confidence) and ``NAME_panel.png`` (per-branch panel, with a bird's-eye view when the frame's
LiDAR points are known); with the uncertainty, ``uncertainty/NAME.png`` (its KITTI 16-bit encoding,
:func:`semattnet.inference.uncertainty.encode_uncertainty`) and ``uncertainty/NAME.npy`` (float32 metres).
The clouds (PLY, bird's-eye view, and the robot outputs) may leave out the pixels whose uncertainty
exceeds an :class:`~semattnet.inference.uncertainty.UncertaintyLimit`; the depth maps stay dense.
A sink may write into a sub-folder, rename frames, or write only some frames
(``semattnet evaluate`` writes ``predictions/`` and the ``pictures/`` of the first frames this way).

A :class:`RunSink` writes one output for the whole run instead (``latency.json`` here; a bag, a Rerun
recording and the live server in :mod:`semattnet.robotics.sinks`): it is opened before the first frame,
fed each completed frame and finished after the last one (:class:`LatencySink`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.registry import Registry, option
from semattnet.data.io import write_depth, write_image
from semattnet.inference.prediction import Prediction, fusion_confidence, predict_frame
from semattnet.inference.uncertainty import UncertaintyLimit
from semattnet.models.outputs import CONFIDENCE_OUTPUTS, DEPTH_OUTPUTS

if TYPE_CHECKING:  # geometry's point clouds and the stage times are imported where used
    from semattnet.data.frames import Frame
    from semattnet.inference.contract import Completion
    from semattnet.inference.timing import StageTimes

__all__ = [
    "SINKS",
    "ColorPngSink",
    "DepthPngSink",
    "LatencySink",
    "NpySink",
    "OutputSettings",
    "PanelOptions",
    "PanelSink",
    "PlyOptions",
    "PlySink",
    "Prediction",
    "RunSink",
    "Sink",
    "SinkOptions",
    "UncertaintyNpySink",
    "UncertaintyPngSink",
    "default_sinks",
    "fusion_confidence",
    "list_sinks",
    "output_files",
    "outputs_read",
    "predict_frame",
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
#: The robot sinks register from :mod:`semattnet.robotics` (which imports this layer, never the reverse), named
#: here by their modules and imported on first read. Every registered sink runs through the suite in
#: ``tests/registry/test_sinks.py``.
SINKS: Registry[Sink] = Registry("sink", homes=(__name__, "semattnet.robotics.sinks", "semattnet.robotics.live"))


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


@dataclass(frozen=True)
class _DepthPng(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [DepthPngSink()]


@dataclass(frozen=True)
class _ColorPng(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [ColorPngSink()]


@dataclass(frozen=True)
class _Npy(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [NpySink()] * settings.npy


@dataclass(frozen=True)
class _UncertaintyPng(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [UncertaintyPngSink()] * settings.uncertainty


@dataclass(frozen=True)
class _UncertaintyNpy(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [UncertaintyNpySink()] * (settings.uncertainty and settings.npy)


@dataclass(frozen=True)
class PlyOptions(SinkOptions):
    """``--ply``."""

    needs_recording: ClassVar[bool] = True
    clouds: ClassVar[str] = "always"
    ply: bool = option("--ply", type="flag", help="With --kitti-raw or --bag: also write a binary PLY point cloud.")

    def sinks(self, settings: OutputSettings) -> list[Sink]:
        s = settings
        return [PlySink(max_depth=s.max_depth, top_crop=s.top_crop, max_uncertainty=s.max_uncertainty)] * self.ply


@dataclass(frozen=True)
class PanelOptions(SinkOptions):
    """``--panel``."""

    clouds: ClassVar[str] = "recording"
    panel: bool = option(
        "--panel", type="flag", help="Also write the per-branch panel (with --kitti-raw: a bird's-eye view)."
    )

    def sinks(self, settings: OutputSettings) -> list[Sink]:
        s = settings
        return [PanelSink(max_depth=s.max_depth, top_crop=s.top_crop, max_uncertainty=s.max_uncertainty)] * self.panel


@dataclass(frozen=True)
class _Latency(SinkOptions):
    def sinks(self, settings: OutputSettings) -> list[Sink]:
        return [LatencySink(timer=settings.timer)]


def list_sinks() -> list[str]:
    """The registered sink names."""
    return SINKS.names()


@register_sink("depth-png", option="--out", options=_DepthPng)
class DepthPngSink(Sink):
    """``NAME.png``: the KITTI 16-bit depth (``metres * 256``, 0 = hole)."""

    role: ClassVar[str] = "depth"

    def reads(self) -> frozenset[str]:
        return DEPTH_OUTPUTS

    def save(self, path: Path, pred: Prediction) -> None:
        write_depth(path, pred.png, overwrite=True, compress_level=pred.compress_level)


@register_sink("color-png", option="--out", options=_ColorPng)
@dataclass
class ColorPngSink(Sink):
    """``NAME_color.png``: the stored depth in colour."""

    suffix: str = "_color.png"

    def reads(self) -> frozenset[str]:
        return DEPTH_OUTPUTS

    def save(self, path: Path, pred: Prediction) -> None:
        from semattnet.viz.depth import colorize_depth

        write_image(path, colorize_depth(pred.stored), overwrite=True, compress_level=pred.compress_level)


@register_sink("ply", option="--ply", options=PlyOptions)
@dataclass
class PlySink(Sink):
    """``NAME.ply``: the stored depth back-projected (camera frame: x right, y down, z forward, metres),
    pixels deeper than ``max_depth`` or in the top ``top_crop`` rows left out, with the image's colours
    and (for SemAttNet) the largest fusion weight as ``confidence``."""

    suffix: str = ".ply"
    max_depth: float = 80.0
    top_crop: int = 0
    max_uncertainty: UncertaintyLimit | None = None  # the pixels above it left out

    def reads(self) -> frozenset[str]:
        return DEPTH_OUTPUTS | CONFIDENCE_OUTPUTS | ({"uncertainty"} if self.max_uncertainty is not None else set())

    def save(self, path: Path, pred: Prediction) -> None:
        from semattnet.geometry import write_ply

        cloud = pred.cloud(self.max_depth, self.top_crop, self.max_uncertainty)
        if len(cloud) == 0:  # named by its cause, not by the staged file write_ply would refuse
            name, limit = pred.frame.name, self.max_uncertainty
            if limit is not None and len(pred.cloud(self.max_depth, self.top_crop)):
                raise InputError(f"{name}: --max-uncertainty {limit}: no pixel's uncertainty is within it, the point "
                                 "cloud would be empty (raise the limit)")  # fmt: skip
            raise InputError(f"{name}: no completed pixel within {self.max_depth:g} m below the top "
                             f"{self.top_crop} rows: the point cloud would be empty")  # fmt: skip
        write_ply(path, cloud, overwrite=True)


@register_sink("npy", option="--npy", options=_Npy)
@dataclass
class NpySink(Sink):
    """``NAME.npy``: the clamped depth, float32 metres (0 = hole), unquantised."""

    suffix: str = ".npy"

    def save(self, path: Path, pred: Prediction) -> None:
        from semattnet._utils.atomic import atomic_path

        with atomic_path(path, suffix=".npy") as tmp:
            np.save(tmp, pred.depth)

    def reads(self) -> frozenset[str]:
        return DEPTH_OUTPUTS


def _uncertainty_of(pred: Prediction) -> tuple[np.ndarray, np.ndarray]:
    """(float32 metres, uint16 encoding) of ``pred``'s uncertainty; a one-line error when the method has none."""
    if pred.uncertainty is None or pred.uncertainty_png is None:
        raise InputError(f"{pred.frame.name}: --uncertainty: the method gives no per-pixel uncertainty")
    return pred.uncertainty, pred.uncertainty_png


@register_sink("uncertainty-png", option="--uncertainty", options=_UncertaintyPng)
@dataclass
class UncertaintyPngSink(Sink):
    """``uncertainty/NAME.png``: the uncertainty in the KITTI 16-bit encoding (``metres * 256``, 0 = none:
    a hole in the depth; :func:`~semattnet.inference.uncertainty.encode_uncertainty`)."""

    folder: str = "uncertainty"
    role: ClassVar[str] = "uncertainty"

    def reads(self) -> frozenset[str]:
        return DEPTH_OUTPUTS | {"uncertainty"}

    def save(self, path: Path, pred: Prediction) -> None:
        write_depth(path, _uncertainty_of(pred)[1], overwrite=True, compress_level=pred.compress_level)


@register_sink("uncertainty-npy", option="--uncertainty", options=_UncertaintyNpy)
@dataclass
class UncertaintyNpySink(Sink):
    """``uncertainty/NAME.npy``: the uncertainty, float32 metres (0 at the holes), unquantised."""

    suffix: str = ".npy"
    folder: str = "uncertainty"

    def reads(self) -> frozenset[str]:
        return DEPTH_OUTPUTS | {"uncertainty"}

    def save(self, path: Path, pred: Prediction) -> None:
        from semattnet._utils.atomic import atomic_path

        values = _uncertainty_of(pred)[0]
        with atomic_path(path, suffix=".npy") as tmp:
            np.save(tmp, values)


@register_sink("panel", option="--panel", options=PanelOptions)
@dataclass
class PanelSink(Sink):
    """``NAME_panel.png``: the per-branch panel (with ground truth and its error map when the frame has
    ground truth) and, when the frame's LiDAR points are known, a bird's-eye view of the cloud."""

    suffix: str = "_panel.png"
    max_depth: float = 80.0
    top_crop: int = 0
    max_uncertainty: UncertaintyLimit | None = None  # the bird's-eye view leaves out the pixels above it

    def save(self, path: Path, pred: Prediction) -> None:
        from semattnet.viz.panels import birds_eye_tile, branch_panel

        frame = pred.frame
        outputs = pred.completion.outputs
        final = "refined_depth" if "refined_depth" in outputs else "fused_depth"
        outputs = {**outputs, final: pred.stored}  # the final map as stored
        extra = []
        if frame.points is not None and frame.calib is not None and frame.K is not None:
            cloud = pred.cloud(self.max_depth, self.top_crop, self.max_uncertainty)
            bev = birds_eye_tile(cloud, frame.points, frame.calib, frame.size, self.max_depth)
            extra.append(("bird's-eye view (LiDAR in magenta)", bev))
        branch_panel(path, frame.rgb, frame.semantic, frame.sparse, outputs, gt=frame.gt, extra=extra)


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


@register_sink("latency", option="--stream", options=_Latency)
@dataclass
class LatencySink(RunSink):
    """``latency.json``: the per-stage times of the run (:class:`semattnet.inference.timing.StageTimes`)."""

    timer: StageTimes | None = None
    name: str = "latency.json"
    replays: ClassVar[bool] = False  # the loop adds the kept frames' recorded times to the timer
    once: ClassVar[bool] = True  # rank 0's timer: every rank's frames

    def reads(self) -> frozenset[str]:
        return frozenset()

    def files(self) -> list[str]:
        return [self.name]

    def finish(self, stage: Path) -> None:
        from semattnet._utils.outputs import write_text

        if self.timer is not None:
            write_text(stage / self.name, self.timer.to_json(), overwrite=True)


def default_sinks(npy: bool = False, panel: bool = False, ply: bool = False, max_depth: float = 80.0,
                  top_crop: int = 0, uncertainty: bool = False,
                  max_uncertainty: UncertaintyLimit | None = None) -> list[Sink]:  # fmt: skip
    """What ``semattnet predict`` writes: ``NAME.png`` and ``NAME_color.png``, then as asked ``NAME.ply``,
    ``NAME.npy``, ``NAME_panel.png`` and (``uncertainty``) ``uncertainty/NAME.png`` (and ``.npy`` with
    ``npy``); ``max_uncertainty``: the PLY and the bird's-eye view leave out the pixels above it."""
    sinks: list[Sink] = [DepthPngSink(), ColorPngSink()]
    sinks += [PlySink(max_depth=max_depth, top_crop=top_crop, max_uncertainty=max_uncertainty)] * ply
    sinks += [NpySink()] * npy + [UncertaintyPngSink()] * uncertainty + [UncertaintyNpySink()] * (uncertainty and npy)
    return sinks + [PanelSink(max_depth=max_depth, top_crop=top_crop, max_uncertainty=max_uncertainty)] * panel


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


def write_prediction(stage: Path, frame: Frame, completion: Completion, sinks: Sequence[Sink],
                     stage_ms: Mapping[str, float] | None = None,
                     compress_level: int | None = None) -> Prediction:  # fmt: skip
    """The one writer: the hole / clamp rule and the quantisation once (:func:`~.sinks.predict_frame`),
    then every sink, into ``stage``. ``stage_ms``: the frame's stage times so far (for the live view);
    ``compress_level``: the PNGs' zlib level (None: :data:`~semattnet.data.io.PNG_COMPRESS_LEVEL`)."""
    pred = predict_frame(frame, completion)
    pred.stage_ms = dict(stage_ms or {})
    if compress_level is not None:
        pred.compress_level = compress_level
    for sink in sinks:
        sink.write(stage, pred)
    return pred
