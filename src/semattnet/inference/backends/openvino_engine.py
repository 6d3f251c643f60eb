"""OpenVINO engine: the cached ONNX export converted once to OpenVINO IR and compiled for the CPU.

The IR (``model.xml``/``.bin``) and OpenVINO's compiled-blob cache live beside the ONNX file
(``<cache>/engines/<key>/``), so a later process only loads them. Precision: ``f32`` (the
default; ``INFERENCE_PRECISION_HINT=f32``, outputs within 1e-4 relative of eager PyTorch) or
``bf16`` (OpenVINO's own default on CPUs with native bfloat16: several times faster there, at a
measured accuracy cost; never chosen automatically) or ``int8`` (the IR quantised by NNCF on
calibration frames, :mod:`semattnet.inference.backends.openvino_int8`; the layers left float32
run in f32; only when asked for).
"""

from __future__ import annotations

import os
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import nn

from semattnet._utils.extras import require
from semattnet.inference.backends._base import HEADS_PREFIX, ExportedGraphEngine, LogFn, graph_outputs
from semattnet.inference.backends._export_cache import (
    cached_onnx,
    engine_dir,
    engine_key,
    intact,
    propagation_settings,
    record_digest,
)
from semattnet.inference.backends.calibration import (
    DEFAULT_CALIBRATION_FRAMES,
    CalibrationFrames,
    anchored,
    resolve_calibration,
)
from semattnet.inference.backends.openvino_int8 import quantized_ir
from semattnet.inference.backends.registry import EngineEntry, EngineRequest, register_engine
from semattnet.models.outputs import DepthCompletionOutput

if TYPE_CHECKING:
    from collections.abc import Sequence

    from openvino import Model, Output

__all__ = ["OpenVinoEngine"]


def _one_of(names: set[str], known: set[str], prefix: str = "\0") -> str:
    """The one name of a model port that we know or that starts with ``prefix`` (IR tensors carry several names)."""
    matches = sorted(n for n in names if n in known or n.startswith(prefix))
    if len(matches) != 1:
        # our own export names the ports: a mismatch is a bug (or an unsupported OpenVINO), not bad input
        raise RuntimeError(f"cannot tell which port {sorted(names)} is; expected one of {sorted(known)}")
    return matches[0]


def _output_names(ports: Sequence[Output]) -> list[str]:
    """The output name of each of a model's result ``ports`` (a field of the typed output or a refinement head)."""
    fields = set(DepthCompletionOutput.__dataclass_fields__)
    return [_one_of(port.get_names(), fields, HEADS_PREFIX) for port in ports]


def _cut(ov: ModuleType, model: Model, asked: frozenset[str]) -> tuple[Model, list[str]]:
    """``model`` (an ``ov.Model``) with only the results that the fields ``asked`` need (same parameters), and their
    names in order (a compiled port may carry the names of several results of one tensor: named here, before)."""
    results = dict(zip(_output_names(model.outputs), model.get_results(), strict=True))
    kept = graph_outputs(list(results), asked)
    cut = ov.Model([results[name] for name in kept], model.get_parameters(), f"{model.get_friendly_name()}-cut")
    return cut, kept


class OpenVinoEngine(ExportedGraphEngine):
    """A compiled OpenVINO CPU model at one ``size`` (LATENCY hint, all of this process's threads); ``outputs``:
    only the graph those fields need (module doc)."""

    backend = "openvino"

    def __init__(
        self,
        model: nn.Module,
        size: tuple[int, int],
        needs_semantic: bool,
        precision: str = "f32",
        cache_dir: str | os.PathLike[str] | None = None,
        log: LogFn | None = None,
        calibration: CalibrationFrames = None,
        calibration_frames: int = DEFAULT_CALIBRATION_FRAMES,
        outputs: frozenset[str] | None = None,
    ) -> None:
        super().__init__(size, precision, needs_semantic)
        ov = require("openvino", "the openvino backend")
        folder = engine_dir(engine_key(model, size, extra=f"openvino-{ov.__version__}"), cache_dir)
        xml = folder / "model.xml"
        core = ov.Core()
        if not (intact(xml, log) and intact(xml.with_suffix(".bin"), log)):  # verified, not trusted
            onnx_path = cached_onnx(model, size, folder, log)
            # IR first (float32 weights: no fp16 compression), so later processes skip the ONNX file
            ov.save_model(core.read_model(str(onnx_path)), str(xml), compress_to_fp16=False)
            for part in (xml, xml.with_suffix(".bin")):
                record_digest(part)
            for done in (onnx_path, onnx_path.with_name(f"{onnx_path.name}.sha256")):  # the IR holds the weights
                done.unlink(missing_ok=True)
        if precision == "int8":  # the quantised IR (cached per calibration); its float layers in f32
            frames = resolve_calibration(calibration, size, calibration_frames)
            if getattr(getattr(model, "config", None), "depth_channels", 1) == 2:  # a generalist's network
                frames = anchored(frames)
            xml = quantized_ir(ov, xml, frames, log)
        hint = "f32" if precision == "int8" else precision
        config = {
            "PERFORMANCE_HINT": "LATENCY",
            "INFERENCE_PRECISION_HINT": hint,
            "INFERENCE_NUM_THREADS": torch.get_num_threads(),
            "CACHE_DIR": str(xml.parent / "blobs"),
        }
        if outputs is None:
            self.compiled = core.compile_model(str(xml), "CPU", config)
            self.output_names = _output_names(self.compiled.outputs)
        else:
            graph, self.output_names = _cut(ov, core.read_model(str(xml)), outputs)
            self.compiled = core.compile_model(graph, "CPU", config)
        self.request = self.compiled.create_infer_request()
        self.input_names = [_one_of(i.get_names(), {"rgb", "semantic", "sparse"}) for i in self.compiled.inputs]
        self.settings = propagation_settings(model)

    def run_graph(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        # the request's own output buffers (share_outputs), which it reuses on the next call: copies of what the
        # caller keeps (the typed output's maps), not of the refinement heads (~180 MB at 352x1216: a fresh copy
        # a frame costs ~60 ms, mostly page faults), which forward uses up before it returns
        result = self.request.infer([feeds[name] for name in self.input_names], share_outputs=True)
        arrays = {name: result[port] for name, port in zip(self.output_names, self.compiled.outputs, strict=True)}
        return {name: a if name.startswith(HEADS_PREFIX) else a.copy() for name, a in arrays.items()}


def _build(model: nn.Module, r: EngineRequest) -> OpenVinoEngine:
    return OpenVinoEngine(
        model.cpu(),
        r.fixed_size(),
        r.needs_semantic,
        r.precision,
        r.cache_dir,
        r.log,
        calibration=r.calibration,
        calibration_frames=r.calibration_frames,
        outputs=r.outputs,
    )


#: int8 is NNCF's quantisation of the IR (:mod:`~semattnet.inference.backends.openvino_int8`; needs ``nncf``).
ENTRY = register_engine(
    EngineEntry(
        "openvino",
        precisions=("f32", "bf16", "int8"),
        devices=("cpu",),
        build=_build,
        package="openvino",
        fixed_size=True,
        auto=True,
        summary="OpenVINO IR compiled for the CPU at one size (cached on disk); int8: NNCF",
    )
)
