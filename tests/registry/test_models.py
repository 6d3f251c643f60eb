"""Every registered model (:func:`semattnet.models.registry.list_models`) at width 1/8 on 32x64 inputs: the
outputs it documents, their shapes, refused inputs, eval-mode determinism and batch independence."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import ClassVar

import pytest
import torch

from semattnet._errors import InputError
from semattnet.models.registry import build_model, list_models
from tests._base import RegistryTester
from tests._helpers import random_inputs

BRANCHES = frozenset({"color_depth", "guided_depth", "color_conf", "guided_conf", "fused_depth"})
SEMANTIC = frozenset({"semantic_depth", "semantic_conf"})
REFINED = frozenset({"refined_s2_depth", "refined_depth"})


@dataclass(frozen=True)
class ModelFixture:
    """The output fields a model returns (the paper's Table 2 row it is)."""

    fields: frozenset[str]

    @property
    def semantic(self) -> bool:
        return "semantic_depth" in self.fields


@cache
def model(name: str) -> torch.nn.Module:
    """One model per name for the whole suite (eval mode, width 1/8, two propagation steps)."""
    torch.manual_seed(0)
    return build_model(name, width=0.125, iterations=2).eval()


def run(name: str, b: int = 1, h: int = 32, w: int = 64, seed: int = 0) -> dict[str, torch.Tensor]:
    with torch.inference_mode():
        return model(name)(**random_inputs(b=b, h=h, w=w, seed=seed)).to_dict()


class TestModels(RegistryTester[ModelFixture]):
    kind = "model"
    fixtures: ClassVar[Mapping[str, ModelFixture]] = {
        "semattnet": ModelFixture(BRANCHES | SEMANTIC | REFINED),
        "semattnet_backbone": ModelFixture(BRANCHES | SEMANTIC),
        "table2_a": ModelFixture(BRANCHES),
        "table2_b": ModelFixture(BRANCHES),
        "table2_c": ModelFixture(BRANCHES | REFINED),
        "table2_d": ModelFixture(BRANCHES | SEMANTIC),
        "table2_e": ModelFixture(BRANCHES | SEMANTIC | REFINED),
        "semattnet_rt_s": ModelFixture(BRANCHES | SEMANTIC | REFINED),
        "semattnet_rt_m": ModelFixture(BRANCHES | SEMANTIC | REFINED),
        "semattnet_rt_l": ModelFixture(BRANCHES | SEMANTIC | REFINED),
        "semattnet_rt_md": ModelFixture(BRANCHES | SEMANTIC | REFINED),
        # the generalists set their own calibrated uncertainty (models.generalist)
        "semattnet_generalist": ModelFixture(BRANCHES | SEMANTIC | REFINED | {"uncertainty"}),
        "semattnet_half_generalist": ModelFixture(BRANCHES | SEMANTIC | REFINED | {"uncertainty"}),
        "semattnet_rt_generalist": ModelFixture(BRANCHES | SEMANTIC | REFINED | {"uncertainty"}),
        "semattnet_rt_half_generalist": ModelFixture(BRANCHES | SEMANTIC | REFINED | {"uncertainty"}),
        "semattnet_rt_l_generalist": ModelFixture(BRANCHES | SEMANTIC | REFINED | {"uncertainty"}),
    }

    @classmethod
    def entries(cls) -> list[str]:
        return list_models()

    def test_smoke(self, entry: str) -> None:
        fx = self.fixture(entry)
        out = run(entry)
        assert set(out) == fx.fields
        assert all(torch.isfinite(t).all() for t in out.values())
        with torch.inference_mode():
            result = model(entry)(**random_inputs(b=1, h=32, w=64))
        assert result.depth is (result.refined_depth if "refined_depth" in fx.fields else result.fused_depth)

    @pytest.mark.parametrize(("b", "h", "w"), [(1, 32, 64), (2, 64, 32)])
    def test_cardinality(self, entry: str, b: int, h: int, w: int) -> None:
        self.fixture(entry)
        assert {k: tuple(t.shape) for k, t in run(entry, b, h, w).items()} == dict.fromkeys(run(entry), (b, 1, h, w))

    def test_exception(self, entry: str) -> None:
        fx, net = self.fixture(entry), model(entry)
        x = random_inputs(b=1, h=32, w=64)
        with pytest.raises(InputError, match="not a positive multiple of 32"):
            net(**random_inputs(b=1, h=33, w=64))
        with pytest.raises(InputError, match="sparse has shape .* batch and size must match"):
            net(x["rgb"], x["semantic"], x["sparse"][..., :32])
        if fx.semantic:
            with pytest.raises(InputError, match="semantic is required"):
                net(x["rgb"], None, x["sparse"])
        else:  # a two-branch model takes no semantic map
            with torch.inference_mode():
                assert torch.equal(net(x["rgb"], None, x["sparse"]).depth, net(**x).depth)

    def test_numerics(self, entry: str) -> None:
        fx = self.fixture(entry)
        both, again = run(entry, b=2), run(entry, b=2)
        first = run(entry, b=2)  # eval mode: the same inputs give the same outputs, call after call
        assert all(torch.equal(both[k], again[k]) and torch.equal(both[k], first[k]) for k in fx.fields)
        x = random_inputs(b=2, h=32, w=64)
        with torch.inference_mode():
            alone = model(entry)(**{k: v[1:] for k, v in x.items()}).to_dict()
        for k in fx.fields:  # batch independence: sample 1 of a batch of 2 equals it alone
            torch.testing.assert_close(both[k][1:], alone[k], rtol=1e-4, atol=1e-4)
        conf = sum(both[k] for k in fx.fields if k.endswith("_conf"))
        torch.testing.assert_close(conf, torch.ones_like(conf), rtol=0, atol=1e-5)  # eq. 12: a softmax
