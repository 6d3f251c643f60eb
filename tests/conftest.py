from __future__ import annotations

from pathlib import Path

import pytest
import torch

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SPEC = SHARED / "spec"


@pytest.fixture(autouse=True)
def _deterministic() -> None:
    torch.manual_seed(0)


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


def _devices() -> list[str]:
    return ["cpu", "cuda"] if torch.cuda.is_available() else ["cpu"]


@pytest.fixture(params=_devices())
def device(request: pytest.FixtureRequest) -> torch.device:
    """Every available device (CPU always; CUDA where present)."""
    return torch.device(request.param)


@pytest.fixture(params=[torch.float32, torch.float64], ids=["float32", "float64"])
def dtype(request: pytest.FixtureRequest) -> torch.dtype:
    """The floating-point types the numerics are tested in on every device."""
    return request.param
