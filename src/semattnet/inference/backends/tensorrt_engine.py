"""TensorRT engine (CUDA): the BN-folded network compiled by Torch-TensorRT at one size, the
CSPN++ propagation after it in PyTorch (float32, :func:`~semattnet.inference.backends.output_from_arrays`).

``pip install 'semattnet[tensorrt]'`` (``torch-tensorrt``, which brings ``tensorrt``); without it,
or without CUDA, building the engine fails with a one-line error. ``precision="fp16"`` lets
TensorRT pick float16 kernels for the network. Not measured on a GPU in this project yet:
``benchmarks/gpu.py`` checks its parity and latency where a GPU is present.
"""

from __future__ import annotations

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.extras import require
from semattnet.inference.backends._base import HEADS_PREFIX, InferenceEngine, output_from_arrays
from semattnet.inference.backends._export_cache import propagation_settings
from semattnet.inference.backends.registry import EngineEntry, EngineRequest, register_engine
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.semattnet import SemAttNet

__all__ = ["TensorRTEngine", "network_outputs"]


def network_outputs(
    net: SemAttNet, rgb: torch.Tensor, semantic: torch.Tensor | None, sparse: torch.Tensor
) -> dict[str, torch.Tensor]:
    """The network part's outputs by name (the backbone's maps and the ``refinement.*`` heads)."""
    out, heads = net.forward_network(rgb=rgb, semantic=semantic, sparse=sparse)
    return out.to_dict() | heads.to_dict(HEADS_PREFIX)


class _Network(nn.Module):
    """Positional inputs, a tuple of outputs in ``names`` order (what Torch-TensorRT compiles)."""

    def __init__(self, net: SemAttNet, names: list[str], semantic: bool) -> None:
        super().__init__()
        self.net, self.names, self.semantic = net, names, semantic

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        rgb, semantic, sparse = inputs if self.semantic else (inputs[0], None, inputs[1])
        out = network_outputs(self.net, rgb, semantic, sparse)
        return tuple(out[n] for n in self.names)


class TensorRTEngine(InferenceEngine):
    """A Torch-TensorRT module of the network at one ``size`` on a CUDA ``device``."""

    backend = "tensorrt"

    def __init__(
        self,
        model: nn.Module,
        size: tuple[int, int],
        needs_semantic: bool,
        precision: str = "f32",
        device: torch.device | str = "cuda",
    ) -> None:
        super().__init__(size, precision, needs_semantic)
        device = torch.device(device)
        if device.type != "cuda":
            raise InputError(f"device: the tensorrt backend runs on CUDA, got {device}")
        trt = require("torch_tensorrt", "the tensorrt backend")
        net = fold_batchnorm(model).eval().to(device)
        if not isinstance(net, SemAttNet):
            raise InputError("model: the tensorrt backend needs a refining SemAttNet (with forward_network)")
        h, w = size
        example = [torch.rand(1, 3, h, w, device=device) * 255] * (2 if needs_semantic else 1)
        example.append(torch.rand(1, 1, h, w, device=device) * 80)
        with torch.inference_mode():
            sem = example[1] if needs_semantic else None
            names = list(network_outputs(net, example[0], sem, example[-1]))
        precisions = {torch.float32} | ({torch.float16} if precision == "fp16" else set())
        self.graph = trt.compile(
            _Network(net, names, needs_semantic).eval(), ir="dynamo", inputs=example, enabled_precisions=precisions
        )
        self.names, self.settings = names, propagation_settings(model)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        self.check_size(rgb)
        inputs = (rgb, semantic, sparse) if self.needs_semantic else (rgb, sparse)
        with torch.inference_mode():
            arrays = dict(zip(self.names, self.graph(*inputs), strict=True))
        return output_from_arrays({k: v.float() for k, v in arrays.items()}, self.settings)


def _build(model: nn.Module, r: EngineRequest) -> TensorRTEngine:
    return TensorRTEngine(model, r.fixed_size(), r.needs_semantic, r.precision, r.device)


ENTRY = register_engine(
    EngineEntry(
        "tensorrt",
        precisions=("f32", "fp16"),
        devices=("cuda",),
        build=_build,
        package="torch_tensorrt",
        fixed_size=True,
        summary="CUDA: the network compiled by Torch-TensorRT at one size",
    )
)
