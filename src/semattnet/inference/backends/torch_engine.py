"""The eager PyTorch engine: a copy of the model with BatchNorm folded into the convolutions.

Float32 CPU inference also takes the fused C++ propagation kernel (automatic in eval mode), and
the engine runs under ``torch.inference_mode``. ``precision="bf16"`` autocasts the network to
bfloat16 (the propagation stays float32); it pays off only on CPUs with native bfloat16
(:func:`semattnet._utils.cpu.has_native_bf16`) and on CUDA.
"""

from __future__ import annotations

from contextlib import nullcontext

import torch
from torch import nn

from semattnet.inference.backends._base import InferenceEngine
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["TorchEngine"]


class TorchEngine(InferenceEngine):
    """Eager inference on a BN-folded copy of ``model`` (or ``model`` itself, folded, with ``inplace``)."""

    backend = "torch"

    def __init__(self, model: nn.Module, precision: str = "f32", needs_semantic: bool = True,
                 inplace: bool = False) -> None:  # fmt: skip
        super().__init__(None, precision, needs_semantic)
        self.net = fold_batchnorm(model, inplace=inplace).eval()

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        # f32: no autocast context of our own, so a caller's autocast (e.g. fp16 on CUDA) still applies
        cast = torch.autocast(rgb.device.type, dtype=torch.bfloat16) if self.precision == "bf16" else nullcontext()
        with torch.inference_mode(), cast:
            out = self.net(rgb=rgb, semantic=semantic, sparse=sparse)
        return out.map(lambda t: t.float()) if self.precision == "bf16" else out
