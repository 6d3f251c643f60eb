"""The eager PyTorch engine: a copy of the model with BatchNorm folded into the convolutions.

Float32 CPU inference also takes the fused C++ propagation kernel (automatic in eval mode), and
the engine runs under ``torch.inference_mode``. ``precision="bf16"`` autocasts the network to
bfloat16 (the propagation stays float32); it pays off only on CPUs with native bfloat16
(:func:`semattnet._utils.cpu.has_native_bf16`) and on CUDA; ``"fp16"`` (CUDA) autocasts to float16.
On CUDA the propagation runs through ``torch.compile``
(:mod:`semattnet.inference.backends.compiled_propagation`; ``compile_propagation=False`` keeps it eager).
"""

from __future__ import annotations

import dataclasses
from contextlib import nullcontext
from typing import Any

import torch
from torch import nn

from semattnet.inference.backends._base import InferenceEngine
from semattnet.inference.backends.compiled_propagation import compiled_propagation
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["TorchEngine"]

_CAST = {"bf16": torch.bfloat16, "fp16": torch.float16}


class TorchEngine(InferenceEngine):
    """Eager inference on a BN-folded copy of ``model`` (or ``model`` itself, folded, with ``inplace``)."""

    backend = "torch"

    def __init__(self, model: nn.Module, precision: str = "f32", needs_semantic: bool = True,
                 inplace: bool = False, compile_propagation: bool | None = None) -> None:  # fmt: skip
        super().__init__(None, precision, needs_semantic)
        self.net: Any = fold_batchnorm(model, inplace=inplace).eval()  # SemAttNet(Backbone): forward_network, config
        on_cuda = any(p.is_cuda for p in self.net.parameters())
        refines = hasattr(self.net, "forward_network")
        self.compile_propagation = refines and (on_cuda if compile_propagation is None else compile_propagation)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        # f32: no autocast context of our own, so a caller's autocast (e.g. fp16 on CUDA) still applies
        dtype = _CAST.get(self.precision)
        cast = torch.autocast(rgb.device.type, dtype=dtype) if dtype is not None else nullcontext()
        with torch.inference_mode(), cast:
            if self.compile_propagation:  # network eagerly, the propagation (float32) compiled
                out, heads = self.net.forward_network(rgb=rgb, semantic=semantic, sparse=sparse)
                s2, refined = compiled_propagation()(heads, self.net.config.iterations)
                out = dataclasses.replace(out, refined_s2_depth=s2, refined_depth=refined)
            else:
                out = self.net(rgb=rgb, semantic=semantic, sparse=sparse)
        return out.map(lambda t: t.float()) if dtype is not None else out
