"""The model reproduces the authors' code: names, shapes, parameter counts and outputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import semattnet
from tests._reference_weights import fill_reference_weights

#: The authors' outputs and state-dict names, kept in the repository (provenance in fixtures/README.md).
FIXTURES = Path(__file__).resolve().parent / "fixtures"
REFERENCE = FIXTURES / "authors_seed0_b2_64x256.npz"
BACKBONE_OUTPUTS = {
    "color_depth": "rgb_depth",
    "semantic_depth": "semantic_depth",
    "guided_depth": "d_depth",
    "fused_depth": "output",
}
FULL_OUTPUTS = {
    "color_conf": "rgb_conf",
    "semantic_conf": "semantic_conf",
    "guided_conf": "d_conf",
    "color_depth": "rgb_depth",
    "semantic_depth": "semantic_depth",
    "guided_depth": "d_depth",
    "refined_s2_depth": "coarse_depth",
    "refined_depth": "refined_depth",
}


def _authors_entries(kind: str) -> list[tuple[str, tuple[int, ...], str]]:
    rows = []
    for line in (FIXTURES / f"authors_state_dict_{kind}.tsv").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        name, shape, dtype = line.split("\t")
        rows.append((name, tuple(int(v) for v in shape.strip("()").split(",") if v.strip()), dtype))
    return rows


@pytest.fixture(scope="module")
def models() -> dict[str, torch.nn.Module]:
    """The two models on the meta device: the tests read names, shapes, dtypes and counts, and a forward loads
    every state-dict entry first (strict), so a random initialisation of 2 x 360 M parameters (seconds) is not
    made only to be replaced."""
    with torch.device("meta"):
        return {name: semattnet.build_model(name) for name in ("semattnet_backbone", "semattnet")}


@pytest.mark.parametrize(
    ("name", "kind", "count"), [("semattnet_backbone", "backbone", 360_717_636), ("semattnet", "full", 360_957_784)]
)
def test_state_dict_equals_authors(models, name: str, kind: str, count: int) -> None:
    model = models[name]
    ours = [(k, tuple(v.shape), str(v.dtype).removeprefix("torch.")) for k, v in model.state_dict().items()]
    assert ours == _authors_entries(kind)  # same names, shapes, dtypes and order
    assert sum(p.numel() for p in model.parameters()) == count


@pytest.mark.parametrize(
    ("name", "prefix", "pairs"),
    [("semattnet_backbone", "backbone_", BACKBONE_OUTPUTS), ("semattnet", "full_", FULL_OUTPUTS)],
)
def test_outputs_match_authors_code(models, name: str, prefix: str, pairs: dict[str, str]) -> None:
    ref = np.load(REFERENCE)
    model = fill_reference_weights(models[name].to_empty(device="cpu"), seed=0).eval()
    inputs = {
        k: torch.from_numpy(ref[f"input_{src}"])
        for k, src in (("rgb", "rgb"), ("semantic", "semantic"), ("sparse", "d"))
    }
    with torch.inference_mode():
        out = model(**inputs)
    for ours, theirs in pairs.items():
        expected = ref[prefix + theirs]
        got = getattr(out, ours).numpy()
        err = np.abs(got - expected).max()
        assert err <= 1e-4 * np.abs(expected).max(), (
            f"{ours}: max error {err:.3g} vs scale {np.abs(expected).max():.3g}"
        )


def test_reference_weights_differ_between_models(models) -> None:
    """The rule keys on full names: the same layer gets different weights in the two models."""
    from tests._reference_weights import reference_value

    a = reference_value("rgb_conv_init.0.weight", (32, 4, 5, 5))
    b = reference_value("backbone.rgb_conv_init.0.weight", (32, 4, 5, 5))
    assert a.shape == b.shape and not np.array_equal(a, b)
    assert np.abs(a).max() <= 1 / np.sqrt(4 * 25)  # (2u - 1) / sqrt(fan_in)
