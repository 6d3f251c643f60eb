"""The per-frame file sinks (``NAME.png``, ``NAME_color.png``, ``NAME.npy``, ``NAME.ply``, ``NAME_panel.png``,
``uncertainty/NAME.png`` and ``.npy``), the options ``predict`` makes them from, and :func:`default_sinks`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.registry import option
from semattnet.data.io import write_depth, write_image
from semattnet.inference.prediction import Prediction
from semattnet.inference.sinks.base import OutputSettings, Sink, SinkOptions, register_sink
from semattnet.inference.uncertainty import UncertaintyLimit
from semattnet.models.outputs import CONFIDENCE_OUTPUTS, DEPTH_OUTPUTS

__all__ = [
    "FILE_OPTIONS",
    "ColorPngSink",
    "DepthPngSink",
    "NpySink",
    "PanelOptions",
    "PanelSink",
    "PlyOptions",
    "PlySink",
    "UncertaintyNpySink",
    "UncertaintyPngSink",
    "default_sinks",
]


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
                raise InputError(
                    f"{name}: --max-uncertainty {limit}: no pixel's uncertainty is within it, the point "
                    "cloud would be empty (raise the limit)"
                )
            raise InputError(
                f"{name}: no completed pixel within {self.max_depth:g} m below the top "
                f"{self.top_crop} rows: the point cloud would be empty"
            )
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


#: The options of the files ``predict`` writes into OUT, in the order their sinks write (the registry's).
FILE_OPTIONS: tuple[type[SinkOptions], ...] = (
    _DepthPng,
    _ColorPng,
    PlyOptions,
    _Npy,
    _UncertaintyPng,
    _UncertaintyNpy,
    PanelOptions,
)


def default_sinks(settings: OutputSettings | None = None, *asked: SinkOptions) -> list[Sink]:
    """What ``semattnet predict`` writes into OUT, each sink made by its options as ``predict`` makes it:
    ``NAME.png`` and ``NAME_color.png``, the ``.npy`` and ``uncertainty/`` files ``settings`` asks for, and what
    ``asked`` options add (``PlyOptions(ply=True)``: ``NAME.ply``; ``PanelOptions(panel=True)``:
    ``NAME_panel.png``); ``settings``' ``max_depth``, ``top_crop`` and ``max_uncertainty`` select the clouds' pixels.

    Raises:
        InputError: an option that is not one of :data:`FILE_OPTIONS`, or given twice.
    """
    given = {type(o): o for o in asked}
    if len(given) != len(asked) or not set(given) <= set(FILE_OPTIONS):
        names = ", ".join(type(o).__name__ for o in asked)
        raise InputError(f"default_sinks: options {names}: each of {[c.__name__ for c in FILE_OPTIONS]} once")
    s = settings or OutputSettings()
    return [sink for cls in FILE_OPTIONS for sink in given.get(cls, cls()).sinks(s)]
