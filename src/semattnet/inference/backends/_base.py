"""What every inference engine is: an ``nn.Module`` called like the model, returning its typed output."""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence
from contextlib import AbstractContextManager
from dataclasses import fields

import numpy as np
import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.refinement import HEADS_PREFIX, PropagationSettings, RefinementHeads, Workspace, refine

__all__ = [
    "HEADS_PREFIX",
    "ExportedGraphEngine",
    "InferenceEngine",
    "LogFn",
    "StageClock",
    "graph_outputs",
    "output_from_arrays",
]

#: A progress logger the backends call with one line of text (e.g. ``print`` or ``logger.info``).
LogFn = Callable[[str], object]
#: The timing hook of a stage an engine runs inside its call: ``hook(stage)`` is the context the stage runs in
#: (e.g. :meth:`semattnet.inference.timing.StageTimes.time` of the current frame).
StageClock = Callable[[str], AbstractContextManager[object]]

_FIELDS = tuple(f.name for f in fields(DepthCompletionOutput))


class InferenceEngine(nn.Module):
    """``engine(rgb=, semantic=, sparse=)`` -> :class:`~semattnet.models.outputs.DepthCompletionOutput`.

    Inputs as for the model: ``rgb`` (B, 3, H, W) 0..255, ``semantic`` (B, 3, H, W) colour-coded
    0..255 (three-branch models), ``sparse`` (B, 1, H, W) metres, 0 = missing; H, W multiples of 32
    and, for engines compiled for one ``size``, exactly that size.

    Attributes:
        backend: ``"torch"``, ``"onnxruntime"`` or ``"openvino"``.
        size: the (H, W) the engine was compiled for, or ``None`` for any size.
        precision: ``"f32"`` (the default; outputs within 1e-4 relative of the eager model) or ``"bf16"``.
        needs_semantic: whether ``semantic`` is required.
        inner_stages: the stages run inside a call that go through ``on_stage`` when it is set (the ``torch``
            engine's ``propagation``); empty when the call is not split.
        on_stage: the timing hook of those stages (:data:`StageClock`), or None.
    """

    backend: str = "?"
    inner_stages: tuple[str, ...] = ()
    on_stage: StageClock | None = None

    def __init__(self, size: tuple[int, int] | None, precision: str, needs_semantic: bool) -> None:
        super().__init__()
        self.size, self.precision, self.needs_semantic = size, precision, needs_semantic

    def check_size(self, rgb: torch.Tensor) -> None:
        """Refuse inputs of another size than the one the engine was compiled for."""
        if self.size is not None and tuple(rgb.shape[-2:]) != tuple(self.size):
            raise InputError(
                f"this {self.backend} engine was compiled for {self.size[0]}x{self.size[1]} inputs, got "
                f"{rgb.shape[-2]}x{rgb.shape[-1]}; build one per size (optimize_for_inference(..., size=))"
            )

    def extra_repr(self) -> str:
        return f"backend={self.backend}, size={self.size}, precision={self.precision}"


def output_from_arrays(
    arrays: Mapping[str, np.ndarray | torch.Tensor],
    settings: PropagationSettings | None = None,
    workspace: Workspace | None = None,
) -> DepthCompletionOutput:
    """A typed output from named (B, 1, H, W) arrays (missing fields are ``None``).

    Arrays named ``refinement.*`` are the :class:`~semattnet.models.refinement.RefinementHeads` of a
    graph exported without its propagation (:func:`semattnet.weights.export.export_onnx` with
    ``propagation=False``): they are finished and both CSPN++ stages run here with the fused kernel,
    as ``settings`` (the model's steps per kernel size and kernel sizes) say; ``workspace`` keeps the
    affinity buffers across calls (:func:`~semattnet.models.refinement.refine`).
    """
    tensors = {k: torch.as_tensor(np.asarray(v)) if not isinstance(v, torch.Tensor) else v for k, v in arrays.items()}
    heads = {k: v for k, v in tensors.items() if k.startswith(HEADS_PREFIX)}
    unknown = set(tensors) - set(_FIELDS) - set(heads)
    if unknown:
        raise InputError(f"unknown output names {sorted(unknown)}; expected some of {_FIELDS}")
    if heads:
        if settings is None:
            raise InputError("refinement heads without the propagation settings (iterations, kernel sizes)")
        with torch.inference_mode():
            tensors["refined_s2_depth"], tensors["refined_depth"] = refine(
                RefinementHeads.from_dict(heads, settings.kernel_sizes, HEADS_PREFIX, settings.affinity),
                settings.iterations,
                workspace=workspace,
            )
    return DepthCompletionOutput(**{name: tensors.get(name) for name in _FIELDS})  # type: ignore[arg-type]


def graph_outputs(available: Sequence[str], asked: Collection[str] | None) -> list[str]:
    """The outputs of an exported graph (``available``, in order) that the fields ``asked`` of
    :class:`~semattnet.models.outputs.DepthCompletionOutput` need (None: all): those present; for the refined depths
    of a graph without its propagation, its ``refinement.*`` heads (:func:`output_from_arrays` finishes them); for
    ``refined_depth`` of a model without refinement, ``fused_depth`` (its final depth). Fields the graph does not
    compute (``uncertainty``) need nothing."""
    if asked is None:
        return list(available)
    keep = set(asked) & set(available)
    heads = {n for n in available if n.startswith(HEADS_PREFIX)}
    if heads and {"refined_depth", "refined_s2_depth"} & set(asked):
        keep |= heads
    elif "refined_depth" in asked and "refined_depth" not in available:
        keep.add("fused_depth")
    return [n for n in available if n in keep]


class ExportedGraphEngine(InferenceEngine):
    """An engine over the cached ONNX export (network only): subclasses set ``input_names``,
    ``settings`` (the model's propagation, or None) and implement :meth:`run_graph`; the refinement
    heads the graph returns are finished here by :func:`output_from_arrays`."""

    input_names: list[str]
    settings: PropagationSettings | None
    #: the propagation's affinity buffers, reused from frame to frame (no page faults on 180 MB a frame)
    workspace: Workspace

    def __init__(self, size: tuple[int, int] | None, precision: str, needs_semantic: bool) -> None:
        super().__init__(size, precision, needs_semantic)
        self.workspace = {}

    def run_graph(self, feeds: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Output name -> array of one run of the graph on named float32 inputs (the ``refinement.*``
        arrays may be the runtime's own buffers, valid until the next run: :meth:`forward` uses them
        up before it returns)."""
        raise NotImplementedError

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        self.check_size(rgb)
        given = {"rgb": rgb, "semantic": semantic, "sparse": sparse}
        missing = [name for name in self.input_names if given[name] is None]
        if missing:
            raise InputError(f"this {self.backend} engine's graph needs {', '.join(missing)}; got None")
        feeds = {name: t.detach().cpu().float().numpy() for name in self.input_names if (t := given[name]) is not None}
        arrays = self.run_graph(feeds)
        tensors = {n: torch.from_numpy(a).to(rgb.device) for n, a in arrays.items()}
        return output_from_arrays(tensors, self.settings, self.workspace)
