"""Confidence fusion of the branch depths (paper eq. 12)."""

from __future__ import annotations

import math

import pytest
import torch

from semattnet.models.confidence_fusion import confidence_fusion
from tests._base import BaseTester


def _slow_reference(depths: list[torch.Tensor], confs: list[torch.Tensor]) -> torch.Tensor:
    """Eq. 12 pixel by pixel: sum_b exp(C_b) D_b / sum_b exp(C_b)."""
    out = torch.empty_like(depths[0])
    b, _, h, w = out.shape
    for n in range(b):
        for i in range(h):
            for j in range(w):
                e = [math.exp(float(c[n, 0, i, j])) for c in confs]
                out[n, 0, i, j] = sum(ek * float(d[n, 0, i, j]) for ek, d in zip(e, depths, strict=True)) / sum(e)
    return out


class TestConfidenceFusion(BaseTester):
    def test_smoke(self, device: torch.device, dtype: torch.dtype) -> None:
        depths = [torch.rand(1, 1, 4, 5, device=device, dtype=dtype) for _ in range(3)]
        fused, weights = confidence_fusion(depths, [torch.zeros_like(d) for d in depths])
        assert isinstance(fused, torch.Tensor) and len(weights) == 3
        self.assert_close(fused, sum(depths) / 3)  # equal confidences: the plain mean

    @pytest.mark.parametrize(("b", "h", "w"), [(1, 1, 1), (2, 3, 7), (3, 8, 5)])
    def test_cardinality(self, b: int, h: int, w: int) -> None:
        depths = [torch.rand(b, 1, h, w) for _ in range(2)]
        fused, weights = confidence_fusion(depths, [torch.rand(b, 1, h, w) for _ in range(2)])
        assert fused.shape == (b, 1, h, w)
        assert [t.shape for t in weights] == [(b, 1, h, w)] * 2
        self.assert_close(weights[0] + weights[1], torch.ones(b, 1, h, w))

    def test_exception(self) -> None:
        with pytest.raises(RuntimeError):  # torch.cat refuses mismatched sizes
            confidence_fusion([torch.rand(1, 1, 2, 2), torch.rand(1, 1, 3, 3)], [torch.rand(1, 1, 2, 2)] * 2)

    def test_numerics(self) -> None:
        g = torch.Generator().manual_seed(3)
        depths = [torch.rand(2, 1, 3, 4, generator=g, dtype=torch.float64) * 80 for _ in range(3)]
        confs = [torch.randn(2, 1, 3, 4, generator=g, dtype=torch.float64) * 3 for _ in range(3)]
        fused, _ = confidence_fusion(depths, confs)
        self.assert_close(fused, _slow_reference(depths, confs))
        # hand value: weights e^0 : e^0 : e^ln2 = 1 : 1 : 2 -> (10 + 20 + 2 * 40) / 4
        one = lambda v: torch.full((1, 1, 1, 1), float(v), dtype=torch.float64)  # noqa: E731
        hand, _ = confidence_fusion([one(10), one(20), one(40)], [one(0), one(0), one(math.log(2))])
        assert hand.item() == pytest.approx(27.5)

    def test_gradcheck(self) -> None:
        d = [torch.rand(1, 1, 2, 3, dtype=torch.float64, requires_grad=True) for _ in range(3)]
        c = [torch.randn(1, 1, 2, 3, dtype=torch.float64, requires_grad=True) for _ in range(3)]
        assert self.gradcheck(lambda *t: confidence_fusion(t[:3], t[3:])[0], *d, *c)
