"""Padding to the model's multiple of 32 and cropping back."""

from __future__ import annotations

import pytest
import torch

from semattnet import crop_padding, pad_to_multiple
from semattnet.models.checks import SIZE_MULTIPLE
from tests._base import BaseTester


class TestPadToMultiple(BaseTester):
    def test_smoke(self) -> None:
        x, pad = pad_to_multiple(torch.ones(1, 1, 375, 1242))
        assert x.shape == (1, 1, 384, 1248) and pad == (9, 0, 3, 3)

    @pytest.mark.parametrize(("h", "w"), [(1, 1), (32, 64), (33, 65), (375, 1242)])
    def test_cardinality(self, h: int, w: int) -> None:
        x, pad = pad_to_multiple(torch.rand(2, 3, h, w))
        assert x.shape[-2] % SIZE_MULTIPLE == 0 and x.shape[-1] % SIZE_MULTIPLE == 0
        assert x.shape[-2] - h < SIZE_MULTIPLE and x.shape[-1] - w < SIZE_MULTIPLE
        assert crop_padding(x, pad).shape == (2, 3, h, w)

    def test_exception(self) -> None:
        with pytest.raises(ValueError, match="not a positive multiple of 32"):
            from semattnet.models.checks import check_inputs

            check_inputs(torch.zeros(1, 3, 33, 64), None, torch.zeros(1, 1, 33, 64), need_semantic=False)

    def test_numerics(self) -> None:
        x = torch.arange(6.0).reshape(1, 1, 2, 3)
        padded, pad = pad_to_multiple(x, multiple=4, value=-1.0)
        # rows go on top (KITTI's sky side), columns split left 0 / right 1
        assert pad == (2, 0, 0, 1)
        assert padded[0, 0, :2].eq(-1).all() and padded[0, 0, :, 3].eq(-1).all()
        assert torch.equal(crop_padding(padded, pad), x)

    def test_gradcheck(self) -> None:
        x = torch.rand(1, 1, 3, 5, dtype=torch.float64, requires_grad=True)
        assert self.gradcheck(lambda t: crop_padding(*pad_to_multiple(t, multiple=4)), x)
