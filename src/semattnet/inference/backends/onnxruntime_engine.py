"""ONNX Runtime engine: the BN-folded model exported to ONNX once (cached), run by onnxruntime."""

from __future__ import annotations

import os

import numpy as np
import torch
from torch import nn

from semattnet._utils.extras import require
from semattnet.inference.backends._base import ExportedGraphEngine, LogFn
from semattnet.inference.backends._export_cache import cached_onnx, engine_dir, engine_key, propagation_settings
from semattnet.inference.backends.registry import EngineEntry, EngineRequest, register_engine

__all__ = ["OnnxRuntimeEngine"]


class OnnxRuntimeEngine(ExportedGraphEngine):
    """A CPU ``onnxruntime.InferenceSession`` over the cached ONNX export at one ``size``."""

    backend = "onnxruntime"

    def __init__(
        self,
        model: nn.Module,
        size: tuple[int, int],
        needs_semantic: bool,
        cache_dir: str | os.PathLike[str] | None = None,
        log: LogFn | None = None,
    ) -> None:
        super().__init__(size, "f32", needs_semantic)
        ort = require("onnxruntime", "the onnxruntime backend")
        folder = engine_dir(engine_key(model, size), cache_dir)
        options = ort.SessionOptions()
        options.intra_op_num_threads = torch.get_num_threads()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.session = ort.InferenceSession(
            str(cached_onnx(model, size, folder, log)), options, providers=["CPUExecutionProvider"]
        )
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.output_names = [o.name for o in self.session.get_outputs()]
        self.settings = propagation_settings(model)

    def run_graph(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return dict(zip(self.output_names, self.session.run(self.output_names, feeds), strict=True))


def _build(model: nn.Module, r: EngineRequest) -> OnnxRuntimeEngine:
    return OnnxRuntimeEngine(model.cpu(), r.fixed_size(), r.needs_semantic, r.cache_dir, r.log)


ENTRY = register_engine(
    EngineEntry(
        "onnxruntime",
        precisions=("f32",),
        devices=("cpu",),
        build=_build,
        package="onnxruntime",
        fixed_size=True,
        summary="the ONNX export run by ONNX Runtime (exported once per frame size, cached on disk)",
    )
)
