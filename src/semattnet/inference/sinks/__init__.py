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

from semattnet.inference.prediction import Prediction, fusion_confidence, predict_frame
from semattnet.inference.sinks.base import (
    SINKS,
    OutputSettings,
    RunSink,
    Sink,
    SinkOptions,
    list_sinks,
    output_files,
    outputs_read,
    register_sink,
    write_prediction,
)
from semattnet.inference.sinks.files import (
    FILE_OPTIONS,
    ColorPngSink,
    DepthPngSink,
    NpySink,
    PanelOptions,
    PanelSink,
    PlyOptions,
    PlySink,
    UncertaintyNpySink,
    UncertaintyPngSink,
    default_sinks,
)
from semattnet.inference.sinks.latency import LatencySink

__all__ = [
    "FILE_OPTIONS",
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
