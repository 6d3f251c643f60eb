"""Depth completion for your own frames: NumPy in, NumPy out, any image size.

    >>> completer = DepthCompleter.from_checkpoint("semattnet.safetensors")
    >>> result = completer(rgb, sparse, semantic)   # (H, W, 3) uint8, (H, W) metres, (H, W, 3) uint8
    >>> result.depth                                # (H, W) float32 metres

Frames are padded to multiples of 32 (rows at the top, columns on both sides) and the outputs
cropped back, so any size works, KITTI's 1242x375 included.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ._device import resolve_device
from .checkpoint import load_model
from .outputs import DepthCompletionOutput
from .validation import crop_padding, pad_to_multiple

__all__ = ["MAX_DEPTH_M", "MIN_DEPTH_M", "Completion", "DepthCompleter", "clamp_for_png"]

#: KITTI's 16-bit encoding represents (0, 255.996] m; 0 means "no prediction".
MIN_DEPTH_M = 1.0 / 256.0
MAX_DEPTH_M = 65535.0 / 256.0


@dataclass
class Completion:
    """A completed frame: ``depth`` (H, W) metres plus every intermediate as (H, W) arrays."""

    depth: np.ndarray
    outputs: dict[str, np.ndarray]


def clamp_for_png(depth: np.ndarray, name: str = "prediction") -> np.ndarray:
    """Clamp to what a KITTI 16-bit PNG can hold, warning when anything was out of range."""
    low, high = int((depth < MIN_DEPTH_M).sum()), int((depth > MAX_DEPTH_M).sum())
    if low or high:
        warnings.warn(f"{name}: clamped {low} pixel(s) below {MIN_DEPTH_M:.4f} m and {high} above "
                      f"{MAX_DEPTH_M:.2f} m to KITTI's 16-bit range", stacklevel=2)  # fmt: skip
    return np.clip(depth, MIN_DEPTH_M, MAX_DEPTH_M)


class DepthCompleter:
    """A model ready for inference on NumPy frames of any size.

    Args:
        model: a SemAttNet (full or backbone) model.
        device: ``auto``, ``cpu`` or ``cuda[:N]``.
        amp: ``none``, ``bf16`` or ``fp16`` autocast (the propagation stays in float32).
    """

    def __init__(self, model: nn.Module, device: str | torch.device = "auto", amp: str = "none") -> None:
        self.device = resolve_device(device)
        self.model = model.to(self.device).eval()
        self.amp = {"bf16": torch.bfloat16, "fp16": torch.float16}.get(amp)
        self.needs_semantic = getattr(model, "config", None) is None or model.config.branches == 3

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, device: str | torch.device = "auto", amp: str = "none"
    ) -> DepthCompleter:
        return cls(load_model(path), device, amp)

    def run(self, rgb: torch.Tensor, semantic: torch.Tensor | None, sparse: torch.Tensor) -> DepthCompletionOutput:
        """Batched tensors (B, C, H, W) of any H, W -> outputs at the same size."""
        rgb_p, pad = pad_to_multiple(rgb)
        sparse_p, _ = pad_to_multiple(sparse)
        sem_p = pad_to_multiple(semantic)[0] if semantic is not None else None
        with torch.inference_mode(), torch.autocast(self.device.type, dtype=self.amp or torch.float32,
                                                    enabled=self.amp is not None):  # fmt: skip
            out = self.model(rgb=rgb_p.to(self.device), semantic=None if sem_p is None else sem_p.to(self.device),
                             sparse=sparse_p.to(self.device))  # fmt: skip
        return out.map(lambda t: crop_padding(t.float(), pad))

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        """Complete one frame: ``rgb`` (H, W, 3) 0..255, ``sparse`` (H, W) metres (0 = none),
        ``semantic`` (H, W, 3) colour-coded 0..255 (required by three-branch models)."""
        rgb, sparse = np.asarray(rgb), np.asarray(sparse)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"rgb must be (H, W, 3), got {rgb.shape}")
        if sparse.shape != rgb.shape[:2]:
            raise ValueError(f"sparse must be (H, W) = {rgb.shape[:2]}, got {sparse.shape}")
        if semantic is None and self.needs_semantic:
            raise ValueError("this model needs a semantic map (see `semattnet segment` or the README)")
        if semantic is not None and np.asarray(semantic).shape != rgb.shape:
            raise ValueError(f"semantic must be {rgb.shape}, got {np.asarray(semantic).shape}")

        def image(a: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1)[None]

        out = self.run(image(rgb), None if semantic is None else image(semantic),
                       torch.from_numpy(np.ascontiguousarray(sparse, dtype=np.float32))[None, None])  # fmt: skip
        arrays = {k: v[0, 0].cpu().numpy() for k, v in out.to_dict().items()}
        return Completion(depth=out.depth[0, 0].cpu().numpy(), outputs=arrays)
