"""Typed results returned by the models' ``forward``."""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, fields, replace

import torch

from semattnet._errors import InputError

__all__ = ["CONFIDENCE_OUTPUTS", "DEPTH_OUTPUTS", "DepthCompletionOutput", "check_output_names"]


@dataclass
class DepthCompletionOutput:
    """Every depth and confidence SemAttNet computes, each (B, 1, H, W), depths in metres.

    Attributes:
        color_depth: colour-guided branch depth D_cg (paper eq. 4).
        semantic_depth: semantic-guided branch depth D_sg (eq. 7); ``None`` for two-branch models.
        guided_depth: depth-guided branch depth D_dg (eq. 10).
        color_conf, semantic_conf, guided_conf: the per-pixel fusion weights of eq. 12, i.e.
            the branch confidences after the softmax across branches (they sum to 1).
        fused_depth: the backbone output D_f (eq. 12).
        refined_s2_depth: after the dilation-2 propagation stage (the authors' "coarse_depth");
            full model only.
        refined_depth: after both propagation stages (the final prediction); full model only.
        uncertainty: per-pixel uncertainty of :attr:`depth` in metres
            (:func:`semattnet.models.uncertainty.depth_uncertainty`); set by whoever holds the sparse input
            (:meth:`semattnet.inference.DepthCompleter.run`), ``None`` straight out of a model.

    An engine asked for some of the fields only (``optimize_for_inference(..., outputs=)``) may leave the
    others ``None``: code that reads a field asks for it.
    """

    color_depth: torch.Tensor
    semantic_depth: torch.Tensor | None
    guided_depth: torch.Tensor
    color_conf: torch.Tensor
    semantic_conf: torch.Tensor | None
    guided_conf: torch.Tensor
    fused_depth: torch.Tensor
    refined_s2_depth: torch.Tensor | None = None
    refined_depth: torch.Tensor | None = None
    uncertainty: torch.Tensor | None = None

    @classmethod
    def from_branches(
        cls, depths: Sequence[torch.Tensor], weights: Sequence[torch.Tensor], fused: torch.Tensor
    ) -> DepthCompletionOutput:
        """A backbone's output: the depths and fusion weights of its two (CG, DG) or three (CG, SG, DG) branches,
        in that order, and the fused depth."""
        if len(depths) not in (2, 3) or len(weights) != len(depths):
            raise InputError(f"branch outputs: 2 or 3 depths and one weight each, got {len(depths)} and {len(weights)}")
        three = len(depths) == 3
        return cls(
            color_depth=depths[0],
            semantic_depth=depths[1] if three else None,
            guided_depth=depths[-1],
            color_conf=weights[0],
            semantic_conf=weights[1] if three else None,
            guided_conf=weights[-1],
            fused_depth=fused,
        )

    @property
    def depth(self) -> torch.Tensor:
        """The model's final prediction: the refined depth if present, else the fused depth."""
        return self.refined_depth if self.refined_depth is not None else self.fused_depth

    def to_dict(self) -> dict[str, torch.Tensor]:
        """The tensors that are present, by attribute name."""
        return {f.name: v for f in fields(self) if (v := getattr(self, f.name)) is not None}

    def map(self, fn: Callable[[torch.Tensor], torch.Tensor]) -> DepthCompletionOutput:
        """A copy with ``fn`` applied to every tensor (e.g. cropping, ``.cpu()``)."""
        mapped = {f.name: fn(v) for f in fields(self) if (v := getattr(self, f.name)) is not None}
        return replace(self, **mapped)


#: The outputs that hold the final prediction (:attr:`DepthCompletionOutput.depth`), as they are asked of an engine:
#: ``refined_depth``, which an engine gives as ``fused_depth`` for a model without refinement.
DEPTH_OUTPUTS: frozenset[str] = frozenset({"refined_depth"})
#: The fusion weights of eq. 12: what a completion's confidence (the point clouds') is read from.
CONFIDENCE_OUTPUTS: frozenset[str] = frozenset({"color_conf", "semantic_conf", "guided_conf"})


def check_output_names(names: Collection[str], what: str = "outputs") -> frozenset[str]:
    """``names`` as a frozenset, each a field of :class:`DepthCompletionOutput`.

    Raises:
        InputError: an unknown name (``what``: the option or argument that gave them).
    """
    known = {f.name for f in fields(DepthCompletionOutput)}
    if isinstance(names, str):
        raise InputError(f"{what}: a collection of output names, got the string {names!r}")
    unknown = sorted(set(names) - known)
    if unknown:
        raise InputError(f"{what}: unknown output(s) {unknown}; expected some of {sorted(known)}")
    return frozenset(names)
