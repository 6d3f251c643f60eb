"""The typed configuration from which every SemAttNet variant is built.

Defaults are the paper's model (Table 2, row g): three branches, SAMMAFB fusion, CSPN++
refinement with atrous propagation, full width. The ablations of Table 2 and smaller models
for CPU training differ only in fields of :class:`SemAttNetConfig`.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Literal

from semattnet._errors import InputError
from semattnet.models.fusion import FEATURE_FUSION_MODES, FusionMode
from semattnet.models.propagation.affinity import AffinityForm, check_affinity_form

__all__ = ["ANCHOR_MODES", "RANGES", "AnchorMode", "RefinementMode", "SemAttNetConfig", "Widths"]

RefinementMode = Literal["authors", "clean"]
#: What the generalist corrects (:mod:`semattnet.models.generalist`): ``"none"`` (the paper's model) or
#: ``"classical"`` (the classical completion, given as an input and corrected by a bounded log residual).
AnchorMode = Literal["none", "classical"]
ANCHOR_MODES: tuple[str, ...] = ("none", "classical")
_SCALES = (1, 2, 4, 8, 16, 32)

#: Allowed ranges (inclusive) of the numeric fields: one home, checked for every config, including
#: configs read from files (a ``config.json`` or checkpoint metadata asking for ``width=64`` or
#: ``iterations=1e9`` would allocate or run without bound).
RANGES: dict[str, tuple[float, float]] = {
    "width": (0.125, 4.0),
    "reduction": (1, 1024),
    "kernel_sizes": (1, 15),
    "iterations": (0, 32),
    "residual_bound": (0.05, 5.0),
    "trust_radius": (0.0, 64.0),
    "work_scale": (1, 4),
}
MAX_KERNELS = 8


def _in_range(name: str, value: object, integer: bool = True) -> None:
    lo, hi = RANGES[name]
    wanted = numbers.Integral if integer else numbers.Real
    if isinstance(value, bool) or not (isinstance(value, wanted) and math.isfinite(value) and lo <= float(value) <= hi):
        kind = "an integer" if integer else "a number"
        raise InputError(f"{name} must be {kind} in [{lo:g}, {hi:g}], got {value!r}")


@dataclass(frozen=True)
class SemAttNetConfig:
    """Architecture options.

    Attributes:
        branches: 3 for colour-, semantic- and depth-guided branches (CG + SG + DG, the paper),
            2 for the two-branch ablation (CG + DG, as PENet's backbone).
        fusion: feature fusion between branches: ``"sammafb"`` (paper), ``"concat"`` or ``"add"``.
        refine: add the CSPN++ refinement with atrous propagation (paper Sec. III-C).
        width: channel multiplier; 1.0 is the paper. Base width is ``round(32 * width)``
            channels at full resolution, doubling at each of the five stride-2 stages.
        reduction: SAMMAFB channel-MLP reduction ratio r.
        kernel_sizes: CSPN++ propagation kernel sizes, blended per pixel by a learned confidence.
        iterations: propagation steps per stage (dilation 2, then dilation 1); 6 + 6 in the paper.
        refinement_mode: ``"authors"`` (default) reproduces the in-place aliasing of the released
            code, which the released weights were trained with; ``"clean"`` is the plain reading of
            the paper. See :mod:`semattnet.models.refinement`.
        palette: the semantic palette the model was trained with (:data:`semattnet.palette.PALETTES`):
            ``"cityscapes"`` (the authors' KITTI maps; checkpoints that record none load as this) or ``"nyu40"``.
        encoder: the branches' encoder (:func:`semattnet.models.encoders.list_encoders`): ``"resnet"`` is
            the paper's network (widths from :class:`Widths`); any other builds the real-time variant
            :mod:`semattnet.models.rt` with the encoder's registered widths times ``width``.
        affinity: how the refinement's guidance becomes a propagation kernel: ``"eq13"`` (the paper's) or
            ``"convex"`` (non-negative weights summing to 1: :func:`semattnet.models.propagation.convex_affinity`).
        anchor: ``"none"`` (the paper) or ``"classical"``: the scale-free generalist
            (:class:`semattnet.models.generalist.Generalist`), whose network reads its depth input as two channels
            (the normalised sparse depth and the normalised classical completion) and whose output is the classical
            completion times a bounded correction.
        residual_bound: the generalist's largest correction of the anchor, in natural-log depth
            (``log(depth / anchor)`` lies in ``(-b, b)``); unused without an anchor.
        trust_radius: the generalist's bound shrinks near the measurements: times ``1 - exp(-r / R)`` at ``r``
            pixels from the nearest point (0: the same bound everywhere).
        work_scale: the generalist's network runs at ``1 / work_scale`` of the input's resolution (1, 2 or 4), its
            anchor at full resolution; the network's outputs and its correction of the anchor are upsampled to the
            input's size (a quarter of the network's work at 2); unused without an anchor.
    """

    branches: Literal[2, 3] = 3
    fusion: FusionMode = "sammafb"
    refine: bool = True
    width: float = 1.0
    reduction: int = 16
    kernel_sizes: tuple[int, ...] = (3, 5, 7)
    iterations: int = 6
    refinement_mode: RefinementMode = "authors"
    palette: str = "cityscapes"
    encoder: str = "resnet"
    affinity: AffinityForm = "eq13"
    anchor: AnchorMode = "none"
    residual_bound: float = 1.0
    trust_radius: float = 4.0
    work_scale: int = 1

    def __post_init__(self) -> None:
        if self.branches not in (2, 3):
            raise InputError(f"branches must be 2 (CG + DG) or 3 (CG + SG + DG), got {self.branches!r}")
        if self.fusion not in FEATURE_FUSION_MODES:
            raise InputError(f"fusion must be one of {FEATURE_FUSION_MODES}, got {self.fusion!r}")
        _in_range("width", self.width, integer=False)  # >= 0.125: at least 4 base channels
        _in_range("reduction", self.reduction)
        if not isinstance(self.kernel_sizes, tuple | list) or not 1 <= len(self.kernel_sizes) <= MAX_KERNELS:
            raise InputError(f"kernel_sizes must be 1 to {MAX_KERNELS} odd sizes, got {self.kernel_sizes!r}")
        for k in self.kernel_sizes:
            _in_range("kernel_sizes", k)
        if any(k % 2 == 0 for k in self.kernel_sizes):
            raise InputError(f"kernel_sizes must be odd and positive, got {self.kernel_sizes!r}")
        _in_range("iterations", self.iterations)
        if self.refinement_mode not in ("authors", "clean"):
            raise InputError(f"refinement_mode must be 'authors' or 'clean', got {self.refinement_mode!r}")
        from semattnet.palette import PALETTES

        if self.palette not in PALETTES:
            raise InputError(f"palette must be one of {tuple(PALETTES)}, got {self.palette!r}")
        object.__setattr__(self, "kernel_sizes", tuple(int(k) for k in self.kernel_sizes))
        check_affinity_form(self.affinity)
        if self.anchor not in ANCHOR_MODES:
            raise InputError(f"anchor must be one of {ANCHOR_MODES}, got {self.anchor!r}")
        _in_range("residual_bound", self.residual_bound, integer=False)
        _in_range("trust_radius", self.trust_radius, integer=False)
        _in_range("work_scale", self.work_scale)
        if self.work_scale not in (1, 2, 4) or (self.work_scale != 1 and self.anchor == "none"):
            raise InputError(f"work_scale: 1, or 2 or 4 for a generalist (anchor='classical'), got {self.work_scale!r}")
        if self.anchor != "none" and not self.refine:
            raise InputError("anchor: the generalist is the refined model; set refine=True")
        from semattnet.models.encoders import encoder_spec

        encoder_spec(self.encoder)  # an unknown name: a one-line UnknownEncoderError listing the registered ones

    @property
    def realtime(self) -> bool:
        """The real-time variant (:mod:`semattnet.models.rt`): any encoder but the paper's ResNet."""
        return self.encoder != "resnet"

    @property
    def depth_channels(self) -> int:
        """Channels of the network's depth input: 1 (sparse metres), 2 with an anchor (sparse, anchor)."""
        return 1 if self.anchor == "none" else 2

    def replace(self, **changes: Any) -> SemAttNetConfig:  # values from JSON / the CLI: __post_init__ checks them
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)

    @property
    def widths(self) -> Widths:
        return Widths.from_config(self)


@dataclass(frozen=True)
class Widths:
    """Channel widths per downsampling factor s in (1, 2, 4, 8, 16, 32).

    ``base[s] = round(32 * width) * s`` is the colour-guided branch.
    ``sg[s]`` / ``dg[s]`` are the semantic- / depth-guided encoder outputs: each stride-2 block
    pair keeps the width of the fused features it consumes, so with concatenation the DG branch
    grows to 192, 448, 960, 1984 channels (paper Sec. III-B, "two more layers") while the SG
    branch matches CG. With addition every branch keeps the CG widths.
    ``fused_sg[s]`` / ``fused_dg[s]`` are the widths entering each fusion block (s = 2 .. 16).
    """

    base: dict[int, int] = field(default_factory=dict)
    sg: dict[int, int] = field(default_factory=dict)
    dg: dict[int, int] = field(default_factory=dict)
    fused_sg: dict[int, int] = field(default_factory=dict)
    fused_dg: dict[int, int] = field(default_factory=dict)

    @classmethod
    def from_config(cls, cfg: SemAttNetConfig) -> Widths:
        b = round(32 * cfg.width)
        base = {s: b * s for s in _SCALES}
        concat = cfg.fusion != "add"
        sg: dict[int, int] = {2: base[2]}
        dg: dict[int, int] = {2: base[2]}
        fused_sg: dict[int, int] = {}
        fused_dg: dict[int, int] = {}
        for s in (2, 4, 8, 16):
            fused_sg[s] = sg[s] + base[s] if concat else base[s]
            # DG fuses its own features with the CG (and SG) decoder features.
            fused_dg[s] = dg[s] + (cfg.branches - 1) * base[s] if concat else base[s]
            sg[2 * s] = fused_sg[s] if concat else base[2 * s]
            dg[2 * s] = fused_dg[s] if concat else base[2 * s]
        return cls(base=base, sg=sg, dg=dg, fused_sg=fused_sg, fused_dg=fused_dg)
