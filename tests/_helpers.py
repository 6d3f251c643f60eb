"""Paths and inputs shared by the tests (fixtures live in conftest.py)."""

from __future__ import annotations

from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SPEC = SHARED / "spec"
#: One real KITTI frame (both cameras) in the official layouts; licence in tests/data/README.md.
SAMPLE = REPO / "tests" / "data" / "kitti_sample"


def random_inputs(
    b: int = 2, h: int = 64, w: int = 96, density: float = 0.05, seed: int = 0
) -> dict[str, torch.Tensor]:
    """Inputs in the model's units: colours 0..255, sparse metres with ~density valid."""
    g = torch.Generator().manual_seed(seed)
    sparse = torch.rand(b, 1, h, w, generator=g) * 70 + 1
    sparse = sparse * (torch.rand(b, 1, h, w, generator=g) < density)
    return {
        "rgb": torch.rand(b, 3, h, w, generator=g) * 255,
        "semantic": torch.rand(b, 3, h, w, generator=g) * 255,
        "sparse": sparse,
    }
