"""Full-size runs (minutes on a CPU): ``pytest -m slow``."""

from __future__ import annotations

import pytest
import torch

import semattnet
from tests._helpers import random_inputs


@pytest.mark.slow
def test_full_width_full_size_forward() -> None:
    model = semattnet.build_model("semattnet").eval()
    x = random_inputs(b=1, h=352, w=1216)
    with torch.inference_mode():
        out = model(**x)
    assert out.refined_depth.shape == (1, 1, 352, 1216)
    assert all(torch.isfinite(t).all() for t in out.to_dict().values())


@pytest.mark.slow
def test_full_width_backward_at_training_crop() -> None:
    model = semattnet.build_model("semattnet").train()
    x = random_inputs(b=1, h=320, w=1216)
    out = model(**x)
    out.refined_depth.mean().backward()
    grads = {n: p.grad for n, p in model.named_parameters()}
    dead = {n for n, g in grads.items() if g is None or not bool(g.abs().sum() > 0)}
    # authors' refinement_mode: exactly dimhalf_s2 and att_12 are bypassed (6 tensors), all else learns
    assert dead == {n for n in grads if n.startswith(("dimhalf_s2.", "att_12."))} and len(dead) == 6
    assert all(bool(torch.isfinite(g).all()) for g in grads.values() if g is not None)
