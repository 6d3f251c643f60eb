"""Paths and inputs shared by the tests (fixtures live in conftest.py)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
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


def agreement(ours: np.ndarray, ref: np.ndarray, radius: int, tol: float = 0.3) -> float:
    """Fraction of ref's points with one of ours within ``radius`` px (Chebyshev) and ``tol`` m in depth."""
    pad = np.pad(ours, radius)
    rv, ru = np.nonzero(ref > 0)
    hit = np.zeros(len(rv), bool)
    for dv in range(-radius, radius + 1):
        for du in range(-radius, radius + 1):
            cand = pad[rv + radius + dv, ru + radius + du]
            hit |= (cand > 0) & (np.abs(cand - ref[rv, ru]) <= tol)
    return float(hit.mean())


def online_cache(monkeypatch, root: Path) -> Path:  # type: ignore[no-untyped-def]
    """Point ``$SEMATTNET_CACHE`` at an empty ``root`` and make every downloader see "online"."""
    monkeypatch.setenv("SEMATTNET_CACHE", str(root))
    monkeypatch.delenv("SEMATTNET_OFFLINE", raising=False)
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setenv("HF_HUB_DISABLE_PROGRESS_BARS", "1")
    try:  # huggingface_hub reads HF_HUB_OFFLINE once, at import: make sure it sees "online"
        from huggingface_hub import constants
    except ImportError:
        return root
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    return root


def mounted_tmpfs(folder: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` (e.g. ``"256k"``) mounted at ``folder`` for a test, unmounted after: a disk that fills up.
    Skips the test without root or ``mount``."""
    import os
    import subprocess

    import pytest

    folder.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)], capture_output=True)
    if res.returncode != 0:
        pytest.skip(f"mount -t tmpfs failed: {res.stderr.decode(errors='replace').strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)
