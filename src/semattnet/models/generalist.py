"""The generalist: a scale-free SemAttNet anchored on the classical completion.

A network trained on one rig learns that rig's depths: a street model predicts street depths in a room. The
generalist removes what ties the network to a rig, in three steps around an unchanged SemAttNet (the paper's
model or a real-time variant, whose depth input has two channels instead of one, see
:attr:`~semattnet.models.config.SemAttNetConfig.depth_channels`):

1. **Scale.** Each frame's depth is divided by its own scale ``s``, the median of its valid sparse depths, and
   multiplied by :data:`REFERENCE_DEPTH`: the network sees every frame as if its median point lay 10 m away,
   in a 3 m room as on an 80 m road. Its output is multiplied back by ``s / REFERENCE_DEPTH``.
2. **Colour.** Each image's channels are standardised (per image and channel: mean 128, standard deviation
   50), so exposure and white balance do not tell the network which rig it is on.
3. **Anchor.** The sparse points that disagree with the classical completion by more than
   :data:`OUTLIER_LOG_RATIO` are left out (returns seen through a foreground edge), and the classical completion
   of the points left, ``A`` (:func:`semattnet.models.anchor.complete_classical`, run in the normalised units so
   that its depth-dependent dilation is scale-free too), is the network's second depth channel and the base its
   output corrects: with ``D_n`` the network's refined depth (paper eq. 13) and ``A_n`` the anchor in the same
   units, the generalist's depth is

   ``D = A * exp(b * tanh(log(D_n / A_n) / b))``  (``b`` = ``config.residual_bound``)

   so ``log(D / A)`` stays within ``(-b, b)``: where the network agrees with the anchor the output is the
   classical completion, and no prediction strays more than a factor ``e^b`` from it. With a ``trust_radius``
   ``R`` the bound shrinks near the measurements: ``b`` becomes ``t b``, ``t = 1 - exp(-r / R)`` at ``r``
   pixels from the nearest point the network reads (0 on a measured pixel, where the anchor is the measurement).

With ``config.work_scale`` ``k`` > 1 only the network runs at ``1 / k`` of the input's resolution: the scale,
the outlier rule, the anchor and the distances stay at full resolution (a classical completion at half
resolution, upsampled, loses its sharp depth edges: the finding on the real frame, docs/guides/generalist.md).
The network reads the frame at its resolution (:func:`work_resolution`: each ``k`` x ``k`` block's nearest
consistent point, its mean colour, its top-left semantic colour, the anchor's block mean; padded to the network's
multiple of 32), and its correction, ``log(D_n / A_k)`` against the anchor at its own resolution, is upsampled
bilinearly onto the full-resolution anchor before the bound (:meth:`Generalist.refine`): a quarter of the
network's work at ``k = 2``, for a CPU at sensor rate.

Nothing depends on the camera's intrinsics or the image size. The uncertainty (:meth:`Generalist.uncertainty`)
adds the correction of the anchor to the model's own terms (:func:`~semattnet.models.uncertainty.depth_uncertainty`)
and is calibrated: ``sigma = k * u + f * D + g * D * r / H``, with ``r / H`` the distance to the nearest point the
network reads as a share of the image's height (far from every measurement the errors grow: on held-out world
streets seen by a depth camera, a median of 24-55 % of the depth at 32 or more pixels from a point, 1-3 % near
one) and ``(k, f, g)`` a buffer fitted on held-out synthetic scenes of every kind and sparse pattern so that in
each of them 91-99 % of the errors lie within ``2 sigma`` (:func:`fit_calibration`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from semattnet._errors import InputError
from semattnet.models.anchor import complete_classical
from semattnet.models.backbone import SemAttNetBackbone
from semattnet.models.checks import SIZE_MULTIPLE, check_inputs, require_sparse
from semattnet.models.config import SemAttNetConfig
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.rt import SemAttNetRT, SemAttNetRTBackbone
from semattnet.models.semattnet import SemAttNet
from semattnet.models.uncertainty import branch_spread, depth_slope, lidar_distance, refinement_change

__all__ = [
    "REFERENCE_DEPTH",
    "Generalist",
    "GeneralistInputs",
    "classical_anchor",
    "consistent_points",
    "fit_calibration",
    "frame_scale",
    "prepare_inputs",
    "standardise_colour",
    "work_resolution",
]

#: The depth (metres) at which the network sees every frame's median sparse point.
REFERENCE_DEPTH = 10.0
#: A sparse point further than this from the anchor (``|log(d / A)|``) is left out of the network's input: a
#: LiDAR return seen through a foreground edge (the sensor sits beside the camera), which the classical
#: completion's dilation and median have already outvoted.
OUTLIER_LOG_RATIO = 0.1
_COLOUR_MEAN, _COLOUR_STD = 128.0, 50.0
_EPS = 1e-3


def frame_scale(sparse: torch.Tensor) -> torch.Tensor:
    """(B, 1, 1, 1): each image's median valid depth (metres), 1 for an image without points."""
    b = sparse.shape[0]
    flat = sparse.detach().float().reshape(b, -1)
    one = torch.ones((), dtype=flat.dtype, device=flat.device)
    points = [row[row > 0] for row in flat]  # a frame's few thousand points, not its pixels
    med = torch.stack([p.median() if p.numel() else one for p in points])  # the lower middle value, as torch's
    med = torch.where(torch.isfinite(med) & (med > 0), med, torch.ones_like(med))
    return med.view(b, 1, 1, 1)


def standardise_colour(rgb: torch.Tensor) -> torch.Tensor:
    """Each image's channels to mean 128 and standard deviation 50, clipped to 0..255 (a flat channel: 128)."""
    mean = rgb.mean(dim=(-2, -1), keepdim=True)
    std = rgb.std(dim=(-2, -1), keepdim=True).clamp_min(1.0)
    return ((rgb - mean) / std * _COLOUR_STD + _COLOUR_MEAN).clamp(0.0, 255.0)


def classical_anchor(sparse: torch.Tensor) -> torch.Tensor:
    """The classical completion of (B, 1, H, W) ``sparse`` metres, the generalist's anchor (no gradient)."""
    with torch.no_grad():
        return complete_classical(sparse.detach().float())


def consistent_points(sparse: torch.Tensor, anchor: torch.Tensor) -> torch.Tensor:
    """``sparse`` without the points further than :data:`OUTLIER_LOG_RATIO` from ``anchor`` (set to 0)."""
    ratio = torch.log(sparse.clamp_min(_EPS)) - torch.log(anchor.clamp_min(_EPS))
    return torch.where((sparse > 0) & (ratio.abs() <= OUTLIER_LOG_RATIO), sparse, torch.zeros_like(sparse))


class GeneralistInputs(NamedTuple):
    """What :meth:`Generalist.prepare` gives the network, and what :meth:`Generalist.finish` needs back."""

    rgb: torch.Tensor  # (B, 3, h, w), standardised colours, at the network's resolution
    depth: torch.Tensor  # (B, 2, h, w): consistent sparse points and anchor, normalised to REFERENCE_DEPTH
    sparse: torch.Tensor  # (B, 1, H, W) metres, as given
    anchor: torch.Tensor  # (B, 1, H, W) metres
    scale: torch.Tensor  # (B, 1, 1, 1): metres per normalised unit
    distance: torch.Tensor  # (B, 1, H, W): pixels to the nearest point the network reads
    semantic: torch.Tensor | None = None  # (B, 3, h, w) colours at the network's resolution, or None
    size: tuple[int, int] | None = None  # the input's (H, W) when the network works at a lower resolution
    net_anchor: torch.Tensor | None = None  # (B, 1, h, w) metres: the anchor at the network's lower resolution


def _pad_to(x: torch.Tensor, k: int, mode: str) -> torch.Tensor:
    """``x`` padded at the bottom and right to multiples of ``k`` (``mode``: "replicate" or "constant" zeros)."""
    ph, pw = -x.shape[-2] % k, -x.shape[-1] % k
    return F.pad(x, (0, pw, 0, ph), mode=mode) if ph or pw else x


def _block_mean(x: torch.Tensor, k: int) -> torch.Tensor:
    """Each ``k`` x ``k`` block's mean of ``x`` (sizes multiples of ``k``): ``avg_pool2d(x, k)`` up to float
    rounding, as ``k * k`` strided slices summed (several times faster on a CPU for an image whose channels
    are its last axis in memory, as a camera frame's are)."""
    total = sum(x[..., i::k, j::k] for i in range(k) for j in range(k))
    assert isinstance(total, torch.Tensor)
    return total / (k * k)


def work_resolution(
    rgb: torch.Tensor, sparse: torch.Tensor, semantic: torch.Tensor | None, k: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """A frame at ``1 / k`` of its resolution (sizes rounded up): each ``k`` x ``k`` block's nearest sparse point
    (the foreground a LiDAR return belongs to), mean colour and top-left semantic colour (a class, never a blend)."""
    far = torch.where(sparse > 0, sparse.float(), torch.full_like(sparse, float("inf"), dtype=torch.float32))
    near = -F.max_pool2d(-_pad_to(far, k, "replicate"), k)
    small = torch.where(torch.isfinite(near), near, torch.zeros_like(near))
    colour = _block_mean(_pad_to(rgb.float(), k, "replicate"), k)
    labels = None if semantic is None else _pad_to(semantic.float(), k, "replicate")[..., ::k, ::k]
    return colour, small, labels


def _network_size(
    rgb: torch.Tensor, sparse: torch.Tensor, semantic: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """The frame padded at the bottom and right to the network's multiple (:data:`SIZE_MULTIPLE`): colours
    replicated, no points in the padding (cropped away with the upsampled outputs)."""
    m = SIZE_MULTIPLE
    return (
        _pad_to(rgb, m, "replicate"),
        _pad_to(sparse, m, "constant"),
        None if semantic is None else _pad_to(semantic, m, "replicate"),
    )


def prepare_inputs(
    rgb: torch.Tensor, sparse: torch.Tensor, semantic: torch.Tensor | None = None, work_scale: int = 1
) -> GeneralistInputs:
    """Steps 1-3 of the module docstring before the network: scale, outliers, anchor (at the input's resolution)
    and the network's inputs at ``1 / work_scale`` of it. Its ``anchor`` alone is a non-learned completion (the
    benchmark's ``anchor`` row)."""
    scale = frame_scale(sparse) / REFERENCE_DEPTH
    normalised = sparse.float() / scale
    points = consistent_points(normalised, classical_anchor(normalised))
    anchor = classical_anchor(points)  # in normalised units too: the classical's depth bands become scale-free
    distance = lidar_distance(points)
    if work_scale == 1:
        depth = torch.cat((points, anchor), dim=1)
        return GeneralistInputs(
            standardise_colour(rgb.float()), depth, sparse, anchor * scale, scale, distance, semantic
        )
    size = (int(sparse.shape[-2]), int(sparse.shape[-1]))
    colour, small, labels = _network_size(*work_resolution(rgb, points, semantic, work_scale))
    small_anchor = _pad_to(
        F.avg_pool2d(_pad_to(anchor, work_scale, "replicate"), work_scale), SIZE_MULTIPLE, "replicate"
    )
    depth = torch.cat((small, small_anchor), dim=1)
    colour = standardise_colour(colour)
    return GeneralistInputs(colour, depth, sparse, anchor * scale, scale, distance, labels, size, small_anchor * scale)


def _network(config: SemAttNetConfig) -> nn.Module:
    if config.anchor == "none":
        raise InputError("Generalist needs a config with an anchor (anchor='classical')")
    return SemAttNetRT(config) if config.realtime else SemAttNet(config)


class Generalist(nn.Module):
    """Scale-free, anchored SemAttNet (module docstring): ``net`` is the paper's model or a real-time variant.

    Parameters are ``net.*`` (the network's own names) and the buffer ``calibration`` = ``(k, f)``.

    Shape:
        rgb (B, 3, H, W) 0..255, semantic (B, 3, H, W) 0..255 (three-branch nets), sparse (B, 1, H, W) metres ->
        :class:`~semattnet.models.outputs.DepthCompletionOutput` in metres, ``uncertainty`` set (calibrated).
    """

    calibration: torch.Tensor

    def __init__(self, config: SemAttNetConfig) -> None:
        super().__init__()
        self.config = config
        self.net = _network(config)
        self.register_buffer("calibration", torch.tensor([1.0, 0.0, 0.0]))

    @staticmethod
    def upgrade_state_dict(state_dict: Mapping[str, torch.Tensor], prefix: str = "") -> dict[str, torch.Tensor]:
        """``state_dict`` as this version reads it: weights calibrated before the distance term (``(k, f)``) get
        ``g = 0``, their uncertainty as it was (:func:`semattnet.weights.load_weights` calls this first)."""
        key, out = prefix + "calibration", dict(state_dict)
        old = out.get(key)
        if old is not None and old.shape == (2,):
            out[key] = torch.cat((old, old.new_zeros(1)))
        return out

    def _load_from_state_dict(
        self,
        state_dict: dict[str, torch.Tensor],
        prefix: str,
        local_metadata: dict[str, object],
        strict: bool,
        missing_keys: list[str],
        unexpected_keys: list[str],
        error_msgs: list[str],
    ) -> None:
        """As :meth:`torch.nn.Module._load_from_state_dict`, the calibration upgraded first (:meth:`upgrade_state_dict`,
        on that one entry)."""
        key = prefix + "calibration"
        if key in state_dict:
            state_dict[key] = self.upgrade_state_dict({key: state_dict[key]}, prefix)[key]
        super()._load_from_state_dict(
            state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys, error_msgs
        )

    def init_depth_heads(self, scale: float = 10.0, shift: float = 15.0) -> None:
        """As the network's (:meth:`SemAttNetBackbone.init_depth_heads`), at :data:`REFERENCE_DEPTH`."""
        backbone = self.net.backbone
        assert isinstance(backbone, SemAttNetBackbone | SemAttNetRTBackbone)
        backbone.init_depth_heads(scale * REFERENCE_DEPTH / 15.0, REFERENCE_DEPTH)

    def prepare(
        self, rgb: torch.Tensor, sparse: torch.Tensor, semantic: torch.Tensor | None = None
    ) -> GeneralistInputs:
        """Steps 1-3 of the module docstring before the network (:func:`prepare_inputs`), at the network's
        resolution (``config.work_scale``)."""
        return prepare_inputs(rgb, sparse, semantic, self.config.work_scale)

    def to_full(self, t: torch.Tensor, inputs: GeneralistInputs) -> torch.Tensor:
        """``t`` at the network's resolution -> the input's (bilinear; itself at ``work_scale`` 1)."""
        if inputs.size is None:
            return t
        k = self.config.work_scale
        up = F.interpolate(t.float(), scale_factor=k, mode="bilinear", align_corners=False)
        return up[..., : inputs.size[0], : inputs.size[1]]

    def finish(
        self, out: DepthCompletionOutput, inputs: GeneralistInputs, uncertainty: bool = True
    ) -> DepthCompletionOutput:
        """The network's output in metres at the input's size (:meth:`to_full`), the refined depth as the bounded
        correction of the anchor (:meth:`refine`), and the calibrated uncertainty (``uncertainty=False``: None)."""
        scale = inputs.scale
        depth_fields = ("color_depth", "semantic_depth", "guided_depth", "fused_depth", "refined_s2_depth")
        changes = {f: getattr(out, f).float() * scale for f in depth_fields if getattr(out, f) is not None}
        net_depth = out.depth.float() * scale
        result = dataclasses.replace(out, **changes, refined_depth=None)  # set below, at the input's size
        if inputs.size is not None:
            result = result.map(lambda t: self.to_full(t, inputs))
        result = dataclasses.replace(result, refined_depth=self.refine(net_depth, inputs))
        if uncertainty:
            result = dataclasses.replace(result, uncertainty=self.uncertainty(result, inputs))
        return result

    def refine(self, net_depth: torch.Tensor, inputs: GeneralistInputs) -> torch.Tensor:
        """The generalist's depth (metres, the input's size) from the network's (metres, its resolution): the
        bounded correction of the anchor (:meth:`correct`); below full resolution the network's log ratio to the
        anchor at its resolution, upsampled, corrects the full-resolution anchor."""
        if inputs.net_anchor is None:
            return self.correct(inputs.anchor, net_depth, inputs.distance)
        ratio = torch.log(net_depth.clamp_min(_EPS)) - torch.log(inputs.net_anchor.clamp_min(_EPS))
        return self.bound(inputs.anchor, self.to_full(ratio, inputs), inputs.distance)

    def correct(self, anchor: torch.Tensor, net_depth: torch.Tensor, distance: torch.Tensor) -> torch.Tensor:
        """``A * exp(t * b * tanh(log(D_n / A) / b))``: the network's depth pulled within a factor ``e^(t b)`` of the
        anchor (both metres) by :meth:`bound`."""
        ratio = torch.log(net_depth.clamp_min(_EPS)) - torch.log(anchor.clamp_min(_EPS))
        return self.bound(anchor, ratio, distance)

    def bound(self, anchor: torch.Tensor, ratio: torch.Tensor, distance: torch.Tensor) -> torch.Tensor:
        """``A * exp(t * b * tanh(r / b))`` for the log ratio ``r``: ``t = 1 - exp(-d / R)`` the trust in the
        network at ``distance`` ``d`` pixels from the nearest point (``R`` = ``config.trust_radius``; 0: ``t = 1``),
        ``b`` = ``config.residual_bound``; 0 where the anchor is 0 (no points)."""
        b, radius = self.config.residual_bound, self.config.trust_radius
        trust = 1.0 - torch.exp(-distance / radius) if radius > 0 else torch.ones_like(distance)
        out = anchor.clamp_min(_EPS) * torch.exp(trust * b * torch.tanh(ratio / b))
        return torch.where(anchor > 0, out, torch.zeros_like(out))

    def uncertainty(self, out: DepthCompletionOutput, inputs: GeneralistInputs) -> torch.Tensor:
        """``sigma = k * u + f * D + g * D * r / H`` metres (module docstring): :meth:`uncertainty_terms`
        calibrated by the buffer ``(k, f, g)``."""
        raw, far = self.uncertainty_terms(out, inputs)
        k, f, g = self.calibration[0], self.calibration[1], self.calibration[2]
        depth = out.depth.float()
        return k * raw + f * depth + g * depth * far

    def uncertainty_terms(
        self, out: DepthCompletionOutput, inputs: GeneralistInputs
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(u, r / H)``: ``u = sqrt(s^2 + c^2 + a^2 + (D - A)^2)`` metres, the model's own terms (the branch spread
        ``s``, the refinement change ``c`` and the anchor term ``a``, :mod:`semattnet.models.uncertainty`, ``a``
        from the points the network reads) and the correction of the anchor; ``r / H`` the distance to the
        nearest of those points as a share of the image's height."""
        depth = out.depth.float()
        s, c = branch_spread(out), refinement_change(out)
        a = (inputs.distance + 1) * depth_slope(depth)
        raw = (s * s + c * c + a * a + (depth - inputs.anchor) ** 2).sqrt()
        return raw, inputs.distance / inputs.distance.shape[-2]

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        """Complete depth: RGB 0..255, semantic colours 0..255, sparse metres -> metres (module docstring)."""
        if self.config.work_scale > 1:  # the network checks its own inputs at its own size: these first
            check_inputs(rgb, semantic, require_sparse(sparse), need_semantic=self.config.branches == 3)
        inputs = self.prepare(rgb, require_sparse(sparse), semantic)
        return self.finish(self.net(inputs.rgb, inputs.semantic, inputs.depth), inputs)


#: The calibration's grid: relative floors ``f`` and distance terms ``g`` tried (``k`` is bisected for each).
_FLOORS = (0.0, 0.005, 0.01, 0.02, 0.04)
_FAR_TERMS = (0.0, 0.1, 0.2, 0.4, 0.8, 1.6, 3.2, 6.4)


def fit_calibration(
    raw: torch.Tensor,
    depth: torch.Tensor,
    far: torch.Tensor,
    error: torch.Tensor,
    cell: torch.Tensor | None = None,
    coverage: tuple[float, float] = (0.91, 0.99),
) -> tuple[float, float, float]:
    """``(k, f, g)`` of ``sigma = k * raw + f * depth + g * depth * far`` (1-D tensors of the pixels with truth;
    ``cell``: each pixel's kind of scene, e.g. street with a depth camera) so that in every cell the share of
    ``|error| <= 2 sigma`` lies within ``coverage``: for each ``(f, g)`` of a grid, ``k`` bisected until the
    worst cell reaches the lower bound; of those whose best cell stays under the upper bound, the sharpest
    (smallest mean ``sigma / depth``); if none does, the one whose best cell is lowest."""
    raw_a, depth_a, far_a, error_a = (t.double().numpy() for t in (raw, depth, far, error))
    cells = np.zeros(raw_a.size, np.int64) if cell is None else np.unique(cell.numpy(), return_inverse=True)[1]
    counts = np.bincount(cells).astype(np.float64)
    low, high = coverage
    best: tuple[bool, float, tuple[float, float, float]] | None = None
    for f in _FLOORS:
        for g in _FAR_TERMS:
            base = f * depth_a + g * depth_a * far_a

            def shares(k: float, base: np.ndarray = base) -> np.ndarray:
                inside = np.abs(error_a) <= 2 * (k * raw_a + base)
                return np.bincount(cells, weights=inside, minlength=counts.size) / counts

            lo, hi = 0.0, 1e3
            for _ in range(40):  # bisection on k: every cell's coverage grows with k
                k = (lo + hi) / 2
                lo, hi = (k, hi) if shares(k).min() < low else (lo, k)
            top = float(shares(hi).max())
            sharpness = float(np.mean((hi * raw_a + base) / np.maximum(depth_a, _EPS)))
            key = (top <= high, -sharpness if top <= high else -top, (hi, f, g))
            if best is None or key[:2] > best[:2]:
                best = key
    assert best is not None
    return best[2]
