"""SAMMAFB and the fusions against hand computations."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from semattnet.models.attention import SAMMAFB
from semattnet.models.confidence_fusion import confidence_fusion
from semattnet.models.fusion import fuse_features, make_fusion_block


def _numpy_sammafb(block: SAMMAFB, x: np.ndarray) -> np.ndarray:
    """Eqs. 1-2 written out in NumPy from the block's weights (eval-mode BN)."""
    sig = lambda v: 1.0 / (1.0 + np.exp(-v))  # noqa: E731
    l1, l3 = block.ChannelGate.mlp[1], block.ChannelGate.mlp[3]
    w0, b0 = l1.weight.detach().numpy(), l1.bias.detach().numpy()
    w1, b1 = l3.weight.detach().numpy(), l3.bias.detach().numpy()
    mlp = lambda v: w1 @ np.maximum(w0 @ v + b0, 0) + b1  # noqa: E731
    out = np.empty_like(x)
    conv = block.SpatialGate.spatial.conv.weight.detach().numpy()[0]  # (2, 7, 7)
    bn = block.SpatialGate.spatial.bn
    for n in range(x.shape[0]):
        f = x[n]
        a_c = sig(mlp(f.mean(axis=(1, 2))) + mlp(f.max(axis=(1, 2))))
        f1 = f * a_c[:, None, None]
        pooled = np.stack((f1.max(axis=0), f1.mean(axis=0)))
        padded = np.pad(pooled, ((0, 0), (3, 3), (3, 3)))
        h, w = f.shape[1:]
        s = np.array([[np.sum(padded[:, i : i + 7, j : j + 7] * conv) for j in range(w)] for i in range(h)])
        s = (s - bn.running_mean.item()) / np.sqrt(bn.running_var.item() + bn.eps) * bn.weight.item() + bn.bias.item()
        out[n] = f1 * sig(s)[None]
    return out


def test_sammafb_matches_equations() -> None:
    block = SAMMAFB(32, reduction=16).eval()
    with torch.no_grad():
        bn = block.SpatialGate.spatial.bn
        bn.running_mean.fill_(0.1)
        bn.running_var.fill_(2.0)
        bn.weight.fill_(1.3)
        bn.bias.fill_(-0.2)
    x = torch.randn(2, 32, 9, 11)
    with torch.no_grad():
        got = block(x).numpy()
    np.testing.assert_allclose(got, _numpy_sammafb(block, x.double().numpy()), rtol=1e-4, atol=1e-5)
    assert block.ChannelGate.mlp[1].out_features == 2


def test_confidence_fusion_hand_values() -> None:
    depths = [torch.full((1, 1, 1, 2), v) for v in (10.0, 20.0, 40.0)]
    confs = [torch.tensor([[[[0.0, 5.0]]]]), torch.tensor([[[[0.0, 0.0]]]]), torch.tensor([[[[np.log(2.0), 0.0]]]])]
    fused, weights = confidence_fusion(depths, confs)
    # pixel 0: exp weights 1, 1, 2 -> (10 + 20 + 80) / 4; pixel 1: e^5, 1, 1
    e5 = np.exp(5.0)
    assert fused[0, 0, 0, 0].item() == pytest.approx(27.5)
    assert fused[0, 0, 0, 1].item() == pytest.approx((10 * e5 + 20 + 40) / (e5 + 2), rel=1e-6)
    assert weights[2][0, 0, 0, 0].item() == pytest.approx(0.5)


@pytest.mark.parametrize(("mode", "channels"), [("add", 4), ("concat", 12), ("sammafb", 12)])
def test_feature_fusion_modes(mode: str, channels: int) -> None:
    feats = [torch.rand(1, 4, 5, 5) for _ in range(3)]
    block = make_fusion_block(mode, channels).eval()  # type: ignore[arg-type]
    out = fuse_features(mode, block, feats)  # type: ignore[arg-type]
    assert out.shape == (1, channels, 5, 5)
    if mode == "add":
        assert torch.allclose(out, feats[0] + feats[1] + feats[2])
    if mode == "concat":
        assert torch.equal(out, torch.cat(feats, 1))
    with pytest.raises(ValueError, match="unknown feature fusion"):
        make_fusion_block("mul", 4)  # type: ignore[arg-type]
