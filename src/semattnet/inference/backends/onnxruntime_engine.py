"""ONNX Runtime engine: the BN-folded model exported to ONNX once (cached), run by onnxruntime."""

from __future__ import annotations

import os

import torch
from torch import nn

from semattnet.inference.backends._base import InferenceEngine, output_from_arrays
from semattnet.inference.backends._export_cache import cached_onnx, engine_dir, engine_key, propagation_steps
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["OnnxRuntimeEngine"]


def _import_onnxruntime():  # type: ignore[no-untyped-def]
    try:
        import onnxruntime
    except ImportError:
        raise ImportError("the onnxruntime backend needs onnxruntime: pip install 'semattnet[onnx]'") from None
    return onnxruntime


class OnnxRuntimeEngine(InferenceEngine):
    """A CPU ``onnxruntime.InferenceSession`` over the cached ONNX export at one ``size``."""

    backend = "onnxruntime"

    def __init__(self, model: nn.Module, size: tuple[int, int], needs_semantic: bool,
                 cache_dir: str | os.PathLike[str] | None = None, log=None) -> None:  # type: ignore[no-untyped-def]  # fmt: skip
        super().__init__(size, "f32", needs_semantic)
        ort = _import_onnxruntime()
        folder = engine_dir(engine_key(model, size), cache_dir)
        options = ort.SessionOptions()
        options.intra_op_num_threads = torch.get_num_threads()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.session = ort.InferenceSession(
            str(cached_onnx(model, size, folder, log)), options, providers=["CPUExecutionProvider"]
        )
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.output_names = [o.name for o in self.session.get_outputs()]
        self.iterations = propagation_steps(model)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        self.check_size(rgb)
        given = {"rgb": rgb, "semantic": semantic, "sparse": sparse}
        feeds = {name: given[name].detach().cpu().float().numpy() for name in self.input_names}
        arrays = self.session.run(self.output_names, feeds)
        return output_from_arrays(
            {n: torch.from_numpy(a).to(rgb.device) for n, a in zip(self.output_names, arrays, strict=True)},
            self.iterations,
        )
