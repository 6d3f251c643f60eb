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
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext

import torch
from torch import nn

from semattnet.inference.backends._base import InferenceEngine
from semattnet.inference.backends.compiled_propagation import compiled_propagation
from semattnet.inference.backends.registry import EngineEntry, EngineRequest, register_engine
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.semattnet import SemAttNet

__all__ = ["TorchEngine"]

_CAST = {"bf16": torch.bfloat16, "fp16": torch.float16}


class TorchEngine(InferenceEngine):
    """Eager inference on a BN-folded copy of ``model`` (or ``model`` itself, folded, with ``inplace``).

    The refined model's ``propagation`` is an inner stage: with :attr:`on_stage` set, the call runs the network
    and then the propagation inside ``on_stage("propagation")`` (CUDA synchronised on both sides), the same
    arithmetic as the model's own forward."""

    backend = "torch"

    def __init__(
        self,
        model: nn.Module,
        precision: str = "f32",
        needs_semantic: bool = True,
        inplace: bool = False,
        compile_propagation: bool | None = None,
    ) -> None:
        super().__init__(None, precision, needs_semantic)
        self.net = fold_batchnorm(model, inplace=inplace).eval()
        on_cuda = any(p.is_cuda for p in self.net.parameters())
        self.inner_stages = ("propagation",) if self.refiner is not None else ()
        if self.refiner is not None:
            self.refiner.propagation_workspace = {}  # the affinities of each frame in the same buffers
        self.compile_propagation = self.refiner is not None and (
            on_cuda if compile_propagation is None else compile_propagation
        )

    @property
    def refiner(self) -> SemAttNet | None:
        """The model when it refines (network, then propagation), else None."""
        return self.net if isinstance(self.net, SemAttNet) else None

    @contextmanager
    def _stage(self, stage: str, device: torch.device) -> Iterator[None]:
        """The block inside :attr:`on_stage` (``stage``), CUDA synchronised before and at its end."""
        if self.on_stage is None:
            yield
            return
        cuda = device.type == "cuda"
        if cuda:
            torch.cuda.synchronize(device)
        with self.on_stage(stage):
            yield
            if cuda:
                torch.cuda.synchronize(device)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        # f32: no autocast context of our own, so a caller's autocast (e.g. fp16 on CUDA) still applies
        dtype = _CAST.get(self.precision)
        cast = torch.autocast(rgb.device.type, dtype=dtype) if dtype is not None else nullcontext()
        with torch.inference_mode(), cast:
            out: DepthCompletionOutput
            net = self.refiner
            if net is not None and (self.compile_propagation or self.on_stage is not None):
                out, heads = net.forward_network(rgb=rgb, semantic=semantic, sparse=sparse)
                with self._stage("propagation", rgb.device):  # compiled: network eagerly, propagation (float32)
                    s2, refined = (
                        compiled_propagation()(heads, net.config.iterations)
                        if self.compile_propagation
                        else net.propagation(heads)
                    )
                out = dataclasses.replace(out, refined_s2_depth=s2, refined_depth=refined)
            else:
                out = self.net(rgb=rgb, semantic=semantic, sparse=sparse)
        return out.map(lambda t: t.float()) if dtype is not None else out


def _build(model: nn.Module, r: EngineRequest) -> TorchEngine:
    return TorchEngine(model.to(r.device), r.precision, r.needs_semantic, r.inplace, r.compile_propagation)


ENTRY = register_engine(
    EngineEntry(
        "torch",
        precisions=("f32", "bf16", "fp16"),
        devices=("cpu", "cuda", "mps"),
        build=_build,
        auto=True,
        summary="eager PyTorch on a BatchNorm-folded copy, fused propagation; any size, any device",
    )
)
