"""The model being adapted, as the frame loop's :class:`~semattnet.inference.contract.Completer`: what the semantic
map filler is bound to and what the held-out metric runs (whole frames, padded to multiples of 32)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from semattnet.inference.backends import needs_semantic
from semattnet.inference.contract import Completion
from semattnet.inference.padding import crop_padding, pad_to_multiple
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["TrainingCompleter", "final_depth", "set_train_mode"]


def final_depth(out: DepthCompletionOutput) -> torch.Tensor:
    """The model's final prediction: the refined depth, or the fused one of a backbone."""
    return out.refined_depth if out.refined_depth is not None else out.fused_depth


def set_train_mode(model: nn.Module, freeze_bn: bool) -> None:
    """Training mode; with ``freeze_bn`` the BatchNorm layers stay in eval mode (their running statistics kept)."""
    model.train()
    if freeze_bn:
        for m in model.modules():
            if isinstance(m, nn.modules.batchnorm._BatchNorm):
                m.eval()


class TrainingCompleter:
    """``model`` (on ``device``) completing one frame in eval mode, without gradients; the caller's mode is
    restored after the call."""

    def __init__(self, model: nn.Module, device: torch.device) -> None:
        self.model, self._device = model, device

    @property
    def needs_semantic(self) -> bool:
        return needs_semantic(self.model)

    @property
    def palette(self) -> str:
        config = getattr(self.model, "config", None)
        return str(getattr(config, "palette", "cityscapes"))

    @property
    def device(self) -> torch.device:
        return self._device

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        def image(a: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1)[None]

        x = [
            image(rgb),
            None if semantic is None else image(semantic),
            torch.from_numpy(np.ascontiguousarray(sparse, dtype=np.float32))[None, None],
        ]
        padded = [None if t is None else pad_to_multiple(t.to(self._device)) for t in x]
        modes = {m: m.training for m in self.model.modules()}
        self.model.eval()
        try:
            with torch.no_grad():
                out = self.model(*(None if p is None else p[0] for p in padded))
        finally:
            for m, mode in modes.items():
                m.training = mode
        pad = padded[0][1] if padded[0] is not None else (0, 0, 0, 0)
        return Completion(crop_padding(final_depth(out), pad)[0, 0].float().cpu().numpy())
