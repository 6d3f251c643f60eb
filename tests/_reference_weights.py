"""The deterministic weight rule of the numerical reference (spec REFERENCE.md).

Any implementation with the authors' state-dict names and shapes can rebuild the same weights
from a seed and compare outputs with the authors' code. Used by the equivalence tests.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
import torch
from torch import nn

__all__ = ["fill_reference_weights", "reference_state_dict", "reference_value"]


def reference_value(name: str, shape: tuple[int, ...], seed: int = 0) -> np.ndarray:
    """The value of one state-dict entry under the rule."""
    rng = np.random.default_rng(zlib.crc32(name.encode()) + seed)
    leaf = name.rsplit(".", 1)[-1]
    if leaf == "num_batches_tracked":
        return np.zeros(shape, dtype=np.int64)
    u = rng.random(shape, dtype=np.float64)
    if leaf == "running_var" or (leaf == "weight" and len(shape) == 1):
        v = 0.75 + 0.5 * u
    elif leaf in ("running_mean", "bias"):
        v = 0.05 * (2.0 * u - 1.0)
    elif leaf == "weight":
        fan_in = shape[1] * math.prod(shape[2:])
        v = (2.0 * u - 1.0) / math.sqrt(fan_in)
    else:
        raise ValueError(f"no reference rule for state-dict entry {name!r}")
    return v.astype(np.float32)


def reference_state_dict(model: nn.Module, seed: int = 0) -> dict[str, torch.Tensor]:
    """The reference weights for every entry of ``model.state_dict()``."""
    return {
        name: torch.from_numpy(reference_value(name, tuple(t.shape), seed)) for name, t in model.state_dict().items()
    }


def fill_reference_weights(model: nn.Module, seed: int = 0) -> nn.Module:
    """Load the reference weights into ``model`` (strict) and return it."""
    model.load_state_dict(reference_state_dict(model, seed), strict=True)
    return model
