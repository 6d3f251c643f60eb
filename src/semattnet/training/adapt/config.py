"""The typed, frozen configuration of a self-supervised adaptation run (``semattnet adapt``)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

from semattnet._errors import InputError

__all__ = ["LOSS_TERMS", "AdaptConfig"]

#: The losses ``adapt`` knows (each switchable): sparse-depth self-supervision, photometric consistency with the
#: frames' other views, edge-aware smoothness.
LOSS_TERMS: tuple[str, ...] = ("sparse", "photometric", "smoothness")


@dataclass(frozen=True)
class AdaptConfig:
    """Everything an adaptation run depends on (saved in its state; a resumed run reads it back).

    Attributes:
        weights: the weights to start from (a registry name, a file or folder, a URL: as ``predict --weights``).
        out: the run folder.
        steps: optimiser steps in total. batch_size: crops per step. lr: Adam's learning rate, cosine to 0 at the
            last step. crop: (H, W) of the random crops, multiples of 32 (smaller frames: their size, rounded down).
        losses: the terms used, of :data:`LOSS_TERMS`.
        hide: (low, high): each step each crop hides a share drawn uniformly in this range of its LiDAR points.
        w_kept: weight of the sparse loss at the kept (input) points, besides the hidden ones (weight 1).
        w_photometric, w_smooth: weights of the photometric and smoothness losses.
        automask: Monodepth2's auto-masking of the photometric loss.
        freeze_bn: BatchNorm layers keep their running statistics and run in eval mode (small batches of one
            recording would otherwise replace statistics learnt over a whole dataset). Trained (False) under
            torchrun, they become SyncBatchNorm (statistics over every rank's crops), which needs CUDA.
        amp: ``none``, ``bf16`` or ``fp16`` autocast, as ``train`` (fp16: CUDA; bf16 on a CPU only with native
            bfloat16). device: ``auto``, ``cpu``, ``cuda[:N]``.
        seed: every random draw (frames, crops, hidden points) follows from it.
        gt_every: every N steps, the KITTI metrics on the held-out frames with ground truth (0: never).
        gt_frames: how many frames with ground truth are held out of training for that metric.
        save_every: the resumable state every N steps (and at the end). on_error: bad frames ``skip`` or ``stop``.
    """

    weights: str
    out: str
    steps: int = 1000
    batch_size: int = 2
    lr: float = 1e-4
    crop: tuple[int, int] = (256, 512)
    losses: tuple[str, ...] = LOSS_TERMS
    hide: tuple[float, float] = (0.2, 0.3)
    w_kept: float = 0.5
    w_photometric: float = 1.0
    w_smooth: float = 1e-3
    automask: bool = True
    freeze_bn: bool = True
    amp: str = "none"
    device: str = "auto"
    seed: int = 0
    gt_every: int = 0
    gt_frames: int = 1
    save_every: int = 100
    on_error: str = "skip"

    def __post_init__(self) -> None:
        for name in ("crop", "losses", "hide"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        self._check_numbers()
        unknown = [t for t in self.losses if t not in LOSS_TERMS]
        if unknown or not self.losses or len(set(self.losses)) != len(self.losses):
            raise InputError(f"losses must be distinct names of {', '.join(LOSS_TERMS)}, got {','.join(self.losses)!r}")
        if self.amp not in ("none", "bf16", "fp16"):
            raise InputError(f"amp must be none, bf16 or fp16, got {self.amp!r}")
        if self.on_error not in ("skip", "stop"):
            raise InputError(f"on_error must be skip or stop, got {self.on_error!r}")

    def _check_numbers(self) -> None:
        def check(name: str, ok: bool, want: str) -> None:
            if not ok:
                raise InputError(f"{name} must be {want}, got {getattr(self, name)!r}")

        def number(x: object) -> bool:
            return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)

        def whole(x: object, low: int) -> bool:
            return isinstance(x, int) and not isinstance(x, bool) and x >= low

        for name in ("steps", "batch_size", "save_every", "gt_frames"):
            check(name, whole(getattr(self, name), 1), "a whole number >= 1")
        for name in ("seed", "gt_every"):
            check(name, whole(getattr(self, name), 0), "a whole number >= 0")
        check("lr", number(self.lr) and self.lr > 0, "a finite number > 0")
        for name in ("w_kept", "w_photometric", "w_smooth"):
            check(name, number(getattr(self, name)) and getattr(self, name) >= 0, "a finite number >= 0")
        check(
            "crop",
            len(self.crop) == 2 and all(whole(v, 32) and v % 32 == 0 for v in self.crop),
            "two multiples of 32 (HxW)",
        )
        low_high = len(self.hide) == 2 and all(number(v) for v in self.hide)
        check("hide", low_high and 0 < self.hide[0] <= self.hide[1] < 1, "a share or a range low..high in (0, 1)")

    def to_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, object]) -> AdaptConfig:
        """From a saved state's dict (unknown keys refused in one line)."""
        known = {f.name for f in dataclasses.fields(cls)}
        if set(data) - known:
            raise InputError(f"unknown adaptation option(s) {sorted(set(data) - known)}")
        return cls(**data)  # type: ignore[arg-type]  # __post_init__ checks every value
