"""Export a model to ONNX or TorchScript for deployment (fixed input size).

Both trace the model with plain tensor ops (the propagation switches to its pad-and-slice form
while tracing) after folding BatchNorm into the convolutions. Inputs are named ``rgb``,
``semantic`` (three-branch models only) and ``sparse``; outputs carry the names of
:class:`~semattnet.models.outputs.DepthCompletionOutput` fields (``refined_depth``, ``fused_depth``,
..., for a backbone ``fused_depth`` and the branch outputs).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import torch
from torch import nn

from semattnet._utils.atomic import atomic_path
from semattnet.models.bn_folding import fold_batchnorm

__all__ = ["export_onnx", "export_torchscript", "output_names"]


class _Flat(nn.Module):
    """The model with positional inputs and a tuple of outputs (what exporters need)."""

    def __init__(self, model: nn.Module, names: list[str], semantic: bool, propagation: bool = True) -> None:
        super().__init__()
        self.model, self.names, self.semantic, self.propagation = model, names, semantic, propagation

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        if self.semantic:
            rgb, semantic, sparse = inputs
        else:
            (rgb, sparse), semantic = inputs, None
        out = _named_outputs(self.model, {"rgb": rgb, "semantic": semantic, "sparse": sparse}, self.propagation)
        return tuple(out[n] for n in self.names)


def _named_outputs(
    model: nn.Module, inputs: dict[str, torch.Tensor | None], propagation: bool
) -> dict[str, torch.Tensor]:
    """The model's outputs by name; without ``propagation``, the network part and the refinement heads."""
    forward_network = getattr(model, "forward_network", None)  # refining models only
    if propagation or forward_network is None:
        return model(**inputs).to_dict()
    out, heads = forward_network(**inputs)
    return {**out.to_dict(), **heads.to_dict()}


def _prepare(
    model: nn.Module, size: tuple[int, int], propagation: bool = True
) -> tuple[_Flat, tuple[torch.Tensor, ...], list[str]]:
    h, w = size
    model = fold_batchnorm(model).cpu().float()
    config = getattr(model, "config", None)
    semantic = config is None or config.branches == 3
    g = torch.Generator().manual_seed(0)
    rgb = torch.rand(1, 3, h, w, generator=g) * 255
    sparse = torch.rand(1, 1, h, w, generator=g) * 80 * (torch.rand(1, 1, h, w, generator=g) < 0.05)
    if getattr(config, "depth_channels", 1) == 2:  # a generalist's network: sparse and anchor
        sparse = torch.cat((sparse, torch.rand(1, 1, h, w, generator=g) * 80), dim=1)
    example = (rgb, torch.rand(1, 3, h, w, generator=g) * 255, sparse) if semantic else (rgb, sparse)
    with torch.inference_mode():
        names = list(_named_outputs(model, dict(zip(_input_names(semantic), example, strict=True)), propagation))
    return _Flat(model, names, semantic, propagation).eval(), example, names


def _input_names(semantic: bool) -> list[str]:
    return ["rgb", "semantic", "sparse"] if semantic else ["rgb", "sparse"]


def output_names(model: nn.Module, size: tuple[int, int] = (64, 96)) -> list[str]:
    """Names of the exported outputs, in order."""
    return _prepare(model, size)[2]


def export_onnx(
    model: nn.Module, path: str | Path, size: tuple[int, int] = (352, 1216), opset: int = 17, propagation: bool = True
) -> Path:
    """Write ``model`` as ONNX for (1, C, H, W) inputs of ``size``; returns the path.

    ``propagation=False`` (refining models) leaves the CSPN++ propagation out: the graph ends at
    the backbone's outputs and the refinement heads (outputs named ``refinement.*``, see
    :class:`~semattnet.models.refinement.RefinementHeads`: per stage one stacked convolution output),
    which our inference engines finish and propagate with the fused kernels. The default writes the
    whole model, for deployment.
    """
    flat, example, names = _prepare(model, size, propagation)
    path = Path(path)
    with atomic_path(path, suffix=".onnx") as tmp, torch.no_grad(), warnings.catch_warnings():
        # the tracer's notes on shape checks and constant folding are expected here (fixed-size export)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        warnings.filterwarnings("ignore", message="Constant folding")
        torch.onnx.export(
            flat,
            example,
            str(tmp),
            input_names=_input_names(flat.semantic),
            output_names=names,
            opset_version=opset,
            dynamo=False,
        )
    return path


def export_torchscript(model: nn.Module, path: str | Path, size: tuple[int, int] = (352, 1216)) -> Path:
    """Write ``model`` as a traced TorchScript module (positional inputs, tuple of outputs)."""
    flat, example, _ = _prepare(model, size)
    path = Path(path)
    with torch.no_grad():
        traced = torch.jit.trace(flat, example, check_trace=False)
    with atomic_path(path, suffix=".pt") as tmp:
        traced.save(str(tmp))
    return path
