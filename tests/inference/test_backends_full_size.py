"""Every backend at the paper's full size (352x1216, full width): parity with eager PyTorch. Slow."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import semattnet
from semattnet.inference.backends import available_backends, optimize_for_inference
from tests._helpers import random_inputs


@pytest.mark.slow
def test_every_backend_matches_eager_at_full_size(tmp_path: Path) -> None:
    model = semattnet.build_model("semattnet").eval()
    x = random_inputs(b=1, h=352, w=1216)
    with torch.inference_mode():
        ref = model(**x).refined_depth
    for backend in available_backends():
        engine = optimize_for_inference(model, backend=backend, size=(352, 1216), cache_dir=tmp_path)
        out = engine(**x).refined_depth
        rel = float((out - ref).abs().max() / ref.abs().max())
        assert rel < 1e-4, (backend, rel)
