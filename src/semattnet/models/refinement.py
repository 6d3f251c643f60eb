"""CSPN++ refinement with atrous convolutions (paper Sec. III-C and "Effectiveness of CSPN++").

The fused backbone depth is refined by 12 propagation steps per kernel size (3, 5, 7): six
with dilation 2 at half-resolution guidance, then six with dilation 1 at full resolution. After
every step the LiDAR measurements are re-injected through a learned mask,
``h = m * d + (1 - m) * h``; each stage blends its per-kernel results with learned per-pixel
kernel confidences (CSPN++'s adaptive kernel size).

The dilation-2 stage runs on the four 2x2 polyphase sub-grids of the depth at once (they are
independent; the half-resolution heads, sparse depth and mask are shared by all four), which is
a full-resolution dilation-2 CSPN with nearest-upsampled heads.

Two readings of the stage hand-over (``SemAttNetConfig.refinement_mode``):

* ``"authors"`` (default; the released weights need it). The authors' code writes the stage-1
  sub-grids back *into the backbone output tensor*. Hence stage 2 starts from the stage-1
  result D' and also uses D' as its fixed input h_0; the learned blend
  ``att_12[0] * D' + att_12[1] * D`` degenerates to D', so ``att_12`` and ``dimhalf_s2`` have no
  effect and receive no gradient. We compute exactly that, without the in-place writes.
* ``"clean"``: the paper's reading. h_0 is the backbone output in both stages; stage 2 starts
  from ``a_0 * D' + a_1 * D`` with ``a = softmax(att_12([F_s1; up(dimhalf_s2(F_s2))]))``.

Parameter names are the authors' (``kernel_conf_layer``, ``mask_layer``,
``iter_guide_layer{3,5,7}`` and their ``_s2`` twins, ``dimhalf_s2``, ``att_12``).
"""

from __future__ import annotations

from collections.abc import Mapping, MutableMapping, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from semattnet._errors import InputError
from semattnet.models._tracing import is_tracing
from semattnet.models.config import SemAttNetConfig
from semattnet.models.layers import convbn, convbnrelu, stacked_heads
from semattnet.models.propagation import (
    AffinityForm,
    AffinityHead,
    downsample_sparse,
    normalise_affinity,
    propagate_pad_and_sum,
    propagate_shifted,
    shift_affinity,
)
from semattnet.models.propagation import cpu_kernel as fused_propagation
from semattnet.models.propagation.export import propagate_functional, shift_functional

__all__ = [
    "HEADS_PREFIX",
    "AtrousCSPNRefinement",
    "PropagationImpl",
    "PropagationSettings",
    "RefinementHeads",
    "RefinementInputs",
    "Workspace",
    "affinity_kernel",
    "propagate_refinement",
    "refine",
    "run_cspn_stage",
]

PropagationImpl = Literal["auto", "pytorch", "naive"]
#: Buffers kept across frames by name (:meth:`RefinementHeads.finish`); what is read from them is
#: valid until the next call with the same workspace.
Workspace = MutableMapping[str, torch.Tensor]
#: Name prefix of the refinement heads' tensors in flat dicts (exported graphs' outputs, :class:`RefinementHeads`).
HEADS_PREFIX = "refinement."


def _can_fuse(*tensors: torch.Tensor) -> bool:
    """The compiled kernel serves float32 CPU inference (no autograd) when it could be built."""
    if torch.is_grad_enabled() and any(t.requires_grad for t in tensors):
        return False
    if is_tracing():
        return False
    if any(t.device.type != "cpu" or t.dtype != torch.float32 for t in tensors):
        return False
    return fused_propagation.available()


def run_cspn_stage(
    start: torch.Tensor,
    h0: torch.Tensor,
    affinities: Sequence[torch.Tensor],
    kernel_conf: torch.Tensor,
    sparse: torch.Tensor,
    mask: torch.Tensor,
    iterations: int,
    impl: PropagationImpl = "auto",
) -> torch.Tensor:
    """Propagate once per kernel size with re-injection, then blend by kernel confidence.

    Args:
        start: (B, C, H, W) initial estimate; h0: (B, C, H, W) fixed input.
        affinities: per kernel size, (B, k*k, H, W) normalised kernels.
        kernel_conf: (B, len(affinities), H, W) softmax weights of the kernel sizes.
        sparse, mask: (B, 1, H, W) depth to re-inject and its learned mask in [0, 1].
        iterations: steps per kernel size.
        impl: ``"auto"`` (the compiled kernel for float32 CPU inference when available, else
            ``"pytorch"``), ``"pytorch"`` (shift once, in-place multiply-adds, autograd) or
            ``"naive"`` (the authors' pad-and-sum, one channel at a time: benchmarks only).
    """
    keep = 1.0 - mask
    blended: torch.Tensor | None = None
    if impl not in ("auto", "pytorch", "naive"):
        raise InputError(f"impl must be auto, pytorch or naive, got {impl!r}")
    fused = impl == "auto" and _can_fuse(start, h0, mask, sparse, *affinities)
    for i, affinity in enumerate(affinities):
        if fused:  # one compiled pass per step (inference on the CPU)
            h = fused_propagation.propagate_iterations(affinity, start, h0, mask, sparse, iterations)
        elif impl == "naive":  # the authors: every polyphase sub-grid on its own, pad-and-sum
            grids = []
            for ch in range(start.shape[1]):
                g = start[:, ch : ch + 1]
                for _ in range(iterations):
                    g = propagate_pad_and_sum(affinity, g, h0[:, ch : ch + 1])
                    g = mask * sparse + keep * g
                grids.append(g)
            h = torch.cat(grids, dim=1)
        elif is_tracing():  # the recorded form: one tensor per tap (see propagation.export)
            tap_list = shift_functional(affinity, 1)
            h = start
            for _ in range(iterations):
                h = mask * sparse + keep * propagate_functional(tap_list, h, h0, 1)
        else:
            shifted = shift_affinity(affinity)
            h = start
            for _ in range(iterations):
                h = propagate_shifted(shifted, h, h0)
                h = mask * sparse + keep * h
        term = kernel_conf[:, i : i + 1] * h
        blended = term if blended is None else blended + term
    assert blended is not None
    return blended


class AtrousCSPNRefinement:
    """Mixin: the CSPN++ heads and the two-stage atrous propagation on an ``nn.Module``."""

    kernel_conf_layer: nn.Sequential
    mask_layer: nn.Sequential
    kernel_conf_layer_s2: nn.Sequential
    mask_layer_s2: nn.Sequential
    dimhalf_s2: nn.Sequential
    att_12: nn.Sequential
    #: How to propagate (see :func:`run_cspn_stage`); ``"naive"`` is the authors' pattern.
    propagation_impl: PropagationImpl = "auto"
    #: Affinity buffers kept across calls (:func:`refine`), set by inference engines on their copy; None: fresh ones.
    propagation_workspace: Workspace | None = None

    def _build_refinement(self, channels: tuple[int, int], config: SemAttNetConfig) -> None:
        """The heads on guidance features of ``channels`` (s1, s2), with ``config``'s kernel sizes, iterations,
        refinement mode and affinity form."""
        channels_s1, channels_s2 = channels
        self._kernel_sizes = tuple(config.kernel_sizes)
        self._affinity = config.affinity
        self._iterations = config.iterations
        self._refinement_mode = config.refinement_mode
        n = len(self._kernel_sizes)
        for suffix, ch in (("", channels_s1), ("_s2", channels_s2)):
            setattr(self, f"kernel_conf_layer{suffix}", convbn(ch, n))
            setattr(self, f"mask_layer{suffix}", convbn(ch, 1))
            for k in self._kernel_sizes:
                setattr(self, f"iter_guide_layer{k}{suffix}", AffinityHead(ch, k))
        self.dimhalf_s2 = convbnrelu(channels_s2, channels_s1, kernel_size=1, padding=0)
        self.att_12 = convbnrelu(2 * channels_s1, 2, kernel_size=3, padding=1)

    def _stage_heads(self, feature: torch.Tensor, suffix: str) -> torch.Tensor:
        """One stage's heads, their convolutions run as one: (B, C, H, W) stacked in the order of
        :meth:`RefinementHeads.split_sizes`."""
        guides: list[AffinityHead] = [getattr(self, f"iter_guide_layer{k}{suffix}") for k in self._kernel_sizes]
        conf_head, mask_head = getattr(self, f"kernel_conf_layer{suffix}"), getattr(self, f"mask_layer{suffix}")
        return stacked_heads(feature, [conf_head, mask_head, *(g.generate for g in guides)])

    def refinement_heads(
        self, depth: torch.Tensor, sparse: torch.Tensor, feature_s1: torch.Tensor, feature_s2: torch.Tensor
    ) -> RefinementHeads:
        """Every head of both stages as the convolutions leave them: the network's part of the refinement."""
        with torch.autocast(device_type=depth.device.type, enabled=False):
            depth, sparse = depth.float(), sparse.float()
            feature_s1, feature_s2 = feature_s1.float(), feature_s2.float()
            heads_s2 = self._stage_heads(feature_s2, "_s2")
            att = None
            if self._refinement_mode != "authors":
                half = F.interpolate(self.dimhalf_s2(feature_s2), scale_factor=2.0, mode="nearest")
                att = torch.softmax(self.att_12(torch.cat((feature_s1, half), dim=1)), dim=1)
            heads = self._stage_heads(feature_s1, "")
        return RefinementHeads(depth, sparse, heads_s2, heads, self._kernel_sizes, att, self._affinity)

    def propagation(self, heads: RefinementHeads) -> tuple[torch.Tensor, torch.Tensor]:
        """Both propagation stages of :func:`propagate_refinement` with this model's settings."""
        return refine(heads, self._iterations, self.propagation_impl, self.propagation_workspace)


@dataclass
class RefinementInputs:
    """What the two propagation stages read: :meth:`RefinementHeads.finish` of the network's heads.

    ``depth`` is the backbone's fused depth D (B, 1, H, W); ``*_s2`` belong to the dilation-2
    stage (half-resolution heads); ``mask*`` are the learned re-injection masks already multiplied
    by the validity of the sparse depth; ``att`` is the stage hand-over blend of the ``"clean"``
    mode (``None`` in the authors' mode). Engines that run the network elsewhere (OpenVINO, ONNX
    Runtime) return the :class:`RefinementHeads` and finish with :func:`refine` in PyTorch.
    """

    depth: torch.Tensor
    sparse: torch.Tensor
    sparse_s2: torch.Tensor
    affinities_s2: list[torch.Tensor]
    kernel_conf_s2: torch.Tensor
    mask_s2: torch.Tensor
    affinities: list[torch.Tensor]
    kernel_conf: torch.Tensor
    mask: torch.Tensor
    att: torch.Tensor | None = None


class PropagationSettings(NamedTuple):
    """What finishing a model's :class:`RefinementHeads` needs: steps per kernel size, the kernel sizes, and
    how the guidance becomes a kernel."""

    iterations: int
    kernel_sizes: tuple[int, ...]
    affinity: AffinityForm = "eq13"


def affinity_kernel(
    guide: torch.Tensor,
    impl: PropagationImpl = "auto",
    workspace: Workspace | None = None,
    name: str = "",
    form: AffinityForm = "eq13",
) -> torch.Tensor:
    """The kernel of ``guide`` (:func:`~semattnet.models.propagation.normalise_affinity`: eq. 13 or the convex
    form); eq. 13 in one pass of the compiled kernel for float32 CPU inference (``impl="auto"``), equal to float
    rounding, written into ``workspace[name]`` when a workspace is given (allocated there on the first call)."""
    if form != "eq13" or not (impl == "auto" and _can_fuse(guide)):
        return normalise_affinity(guide, form)
    if workspace is None:
        return fused_propagation.normalize_affinity(guide)
    b, n, h, w = guide.shape
    out = workspace.get(name)
    if out is None or out.shape != (b, h, n + 1, w):  # the kernel's layout (fused_propagation.rows_layout)
        out = workspace[name] = torch.empty(b, h, n + 1, w)
    return fused_propagation.normalize_affinity(guide, out)


#: The tensors every :class:`RefinementHeads` holds (``att`` only in the clean mode).
_HEAD_TENSORS = ("depth", "sparse", "heads_s2", "heads")


@dataclass
class RefinementHeads:
    """The refinement heads as the network's convolutions leave them, before eq. 13 and the softmax.

    Per stage one tensor, the heads' channels stacked in this order (:meth:`split_sizes`): ``len(kernel_sizes)``
    kernel-confidence logits, one mask logit, then the raw guidance of every kernel size
    (``k*k - 1`` channels each). ``heads_s2`` is at half resolution (dilation-2 stage), ``heads``
    at full resolution. This is what exported graphs return: one output per stage, no split and no
    normalisation in the graph; :meth:`finish` does the rest. ``depth`` is the backbone's fused
    depth D, ``sparse`` the input LiDAR depth, ``att`` the clean mode's stage blend (else None).
    """

    depth: torch.Tensor
    sparse: torch.Tensor
    heads_s2: torch.Tensor
    heads: torch.Tensor
    kernel_sizes: tuple[int, ...]
    att: torch.Tensor | None = None
    affinity: AffinityForm = "eq13"

    def split_sizes(self) -> list[int]:
        """Channels of each head in a stage's stacked tensor: kernel confidences, mask, guidance per kernel size."""
        return [len(self.kernel_sizes), 1, *(k * k - 1 for k in self.kernel_sizes)]

    def _stage(
        self, stacked: torch.Tensor, valid: torch.Tensor, impl: PropagationImpl, workspace: Workspace | None, stage: str
    ) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]:
        sizes = self.split_sizes()
        if stacked.shape[1] != sum(sizes):
            raise InputError(
                f"refinement heads: {stacked.shape[1]} channels, expected {sum(sizes)} for kernel "
                f"sizes {self.kernel_sizes}"
            )
        conf, mask, *guides = torch.split(stacked, sizes, dim=1)
        affinities = [affinity_kernel(g, impl, workspace, f"{stage}.{i}", self.affinity) for i, g in enumerate(guides)]
        return affinities, torch.softmax(conf, dim=1), torch.sigmoid(mask) * valid

    def finish(self, impl: PropagationImpl = "auto", workspace: Workspace | None = None) -> RefinementInputs:
        """The affinities (eq. 13), kernel confidences (softmax) and masks (sigmoid, times the
        validity of the sparse depth) of both stages.

        ``workspace``: buffers the affinities of the compiled kernel are written into, kept by the
        caller across frames (an engine's propagation); the result aliases them.
        """
        with torch.autocast(device_type=self.depth.device.type, enabled=False):
            sparse = self.sparse.float()
            sparse_s2, valid_s2 = downsample_sparse(sparse, 2)
            affinities_s2, conf_s2, mask_s2 = self._stage(self.heads_s2.float(), valid_s2, impl, workspace, "s2")
            valid = (sparse > 0).to(sparse.dtype)
            affinities, conf, mask = self._stage(self.heads.float(), valid, impl, workspace, "s1")
        return RefinementInputs(
            self.depth.float(), sparse, sparse_s2, affinities_s2, conf_s2, mask_s2, affinities, conf, mask, self.att
        )

    def to_dict(self, prefix: str = HEADS_PREFIX) -> dict[str, torch.Tensor]:
        """The tensors by name (``att`` only when set), e.g. for an exported graph's outputs."""
        return {f"{prefix}{n}": v for n in (*_HEAD_TENSORS, "att") if (v := getattr(self, n)) is not None}

    @classmethod
    def from_dict(
        cls,
        tensors: Mapping[str, torch.Tensor],
        kernel_sizes: Sequence[int],
        prefix: str = HEADS_PREFIX,
        affinity: AffinityForm = "eq13",
    ) -> RefinementHeads:
        """The inverse of :meth:`to_dict` (other keys are ignored; ``affinity`` is the model's form)."""
        missing = [n for n in _HEAD_TENSORS if f"{prefix}{n}" not in tensors]
        if missing:
            raise InputError(f"refinement heads: missing {', '.join(prefix + n for n in missing)}")
        t = {n: tensors[f"{prefix}{n}"] for n in _HEAD_TENSORS}
        return cls(**t, kernel_sizes=tuple(kernel_sizes), att=tensors.get(f"{prefix}att"), affinity=affinity)


def refine(
    heads: RefinementHeads, iterations: int, impl: PropagationImpl = "auto", workspace: Workspace | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """The heads finished (:meth:`RefinementHeads.finish`, into ``workspace`` if given) and propagated
    (:func:`propagate_refinement`); the results never alias the workspace."""
    return propagate_refinement(heads.finish(impl, workspace), iterations, impl)


def propagate_refinement(
    inputs: RefinementInputs, iterations: int, impl: PropagationImpl = "auto"
) -> tuple[torch.Tensor, torch.Tensor]:
    """CSPN++ with atrous propagation (module docstring): (after the dilation-2 stage, final), each (B, 1, H, W).

    Stage 1 runs dilation 2 as dilation 1 on the four 2x2 polyphase sub-grids; stage 2 runs
    dilation 1 at full resolution, starting from stage 1's result (authors' mode) or from the
    ``att`` blend of it and D with h_0 = D (clean mode).
    """
    ri = inputs
    with torch.autocast(device_type=ri.depth.device.type, enabled=False):
        grids = F.pixel_unshuffle(ri.depth, 2)  # (B, 4, H/2, W/2): D[a::2, b::2] at channel 2a + b
        refined_grids = run_cspn_stage(
            grids, grids, ri.affinities_s2, ri.kernel_conf_s2, ri.sparse_s2, ri.mask_s2, iterations, impl
        )
        refined_s2 = F.pixel_shuffle(refined_grids, 2)
        if ri.att is None:
            start = h0 = refined_s2
        else:
            start, h0 = ri.att[:, 0:1] * refined_s2 + ri.att[:, 1:2] * ri.depth, ri.depth
        refined = run_cspn_stage(start, h0, ri.affinities, ri.kernel_conf, ri.sparse, ri.mask, iterations, impl)
    return refined_s2, refined
