"""CSPN++ propagation against a slow per-pixel loop of the update in ARCHITECTURE.md."""

from __future__ import annotations

import pytest
import torch

from semattnet.models.propagation import (
    convex_affinity,
    cspn_affinity,
    downsample_sparse,
    normalise_affinity,
    propagate,
    propagate_shifted,
    shift_affinity,
)


def slow_propagate(w: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int) -> torch.Tensor:
    """h'(p) = sum_{t != c} W_t(p - o_t) h(p - o_t) + W_c(p) h0(p), pixel by pixel, in float64."""
    _b, kk, height, width = w.shape
    k = round(kk**0.5)
    r, c = k // 2, kk // 2
    w, h, h0 = w.double(), h.double(), h0.double()
    out = torch.zeros_like(h)
    for y in range(height):
        for x in range(width):
            acc = w[:, c, y, x, None] * h0[:, :, y, x]
            for t in range(kk):
                if t == c:
                    continue
                qy, qx = y - (t // k - r) * dilation, x - (t % k - r) * dilation
                if 0 <= qy < height and 0 <= qx < width:
                    acc = acc + w[:, t, qy, qx, None] * h[:, :, qy, qx]
            out[:, :, y, x] = acc
    return out


@pytest.mark.parametrize("k", [3, 5, 7])
@pytest.mark.parametrize("dilation", [1, 2])
def test_matches_slow_reference(k: int, dilation: int) -> None:
    g = torch.Generator().manual_seed(k * 10 + dilation)
    w = cspn_affinity(torch.randn(2, k * k - 1, 11, 13, generator=g))
    h = torch.rand(2, 3, 11, 13, generator=g) * 50
    h0 = torch.rand(2, 3, 11, 13, generator=g) * 50
    got = propagate(w, h, h0, dilation)
    expected = slow_propagate(w, h, h0, dilation)
    scale = expected.abs().max()
    assert got.dtype == torch.float32
    assert (got.double() - expected).abs().max() <= 2e-6 * scale  # float32 rounding only


def test_shifted_kernel_reused_over_steps() -> None:
    g = torch.Generator().manual_seed(1)
    w = cspn_affinity(torch.randn(1, 24, 9, 10, generator=g))
    h = h0 = torch.rand(1, 1, 9, 10, generator=g)
    shifted = shift_affinity(w)
    a = b = h
    for _ in range(3):
        a = propagate(w, a, h0)
        b = propagate_shifted(shifted, b, h0)
    assert torch.equal(a, b)


@pytest.mark.parametrize(("k", "dilation"), [(3, 1), (5, 2)])
def test_gradcheck(k: int, dilation: int) -> None:
    g = torch.Generator().manual_seed(2)
    w = torch.randn(1, k * k, 5, 6, dtype=torch.float64, generator=g, requires_grad=True)
    h = torch.randn(1, 2, 5, 6, dtype=torch.float64, generator=g, requires_grad=True)
    h0 = torch.randn(1, 2, 5, 6, dtype=torch.float64, generator=g, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b, c: propagate(a, b, c, dilation), (w, h, h0))


def test_affinity_normalisation() -> None:
    guide = torch.randn(2, 24, 5, 6)
    w = cspn_affinity(guide)
    assert w.shape == (2, 25, 5, 6)
    assert torch.allclose(w.sum(1), torch.ones(2, 5, 6), atol=1e-6)  # eq. 13: weights sum to one
    assert torch.allclose(w[:, :12].abs().sum(1) + w[:, 13:].abs().sum(1), torch.ones(2, 5, 6), atol=1e-6)


def test_convex_affinity_gives_each_pixel_a_softmax_of_its_neighbours() -> None:
    """Shifted to the receiving pixels (what each step reads), the convex kernel is the softmax of the guidance
    and a zero centre logit, inside the image; the weights are never negative."""
    guide = torch.randn(2, 8, 5, 6, dtype=torch.float64)
    w = convex_affinity(guide)
    assert w.shape == (2, 9, 5, 6) and bool((w >= 0).all())
    e = guide.exp()
    by_hand = torch.cat((e[:, :4], torch.ones_like(e[:, :1]), e[:, 4:]), 1)
    by_hand = by_hand / by_hand.sum(1, keepdim=True)
    torch.testing.assert_close(shift_affinity(w)[..., 1:-1, 1:-1], by_hand[..., 1:-1, 1:-1])
    torch.testing.assert_close(normalise_affinity(guide, "convex"), w)
    torch.testing.assert_close(normalise_affinity(guide), cspn_affinity(guide))
    with pytest.raises(ValueError, match="affinity must be one of \\('eq13', 'convex'\\), got 'softmax'"):
        normalise_affinity(guide, "softmax")
    assert torch.autograd.gradcheck(convex_affinity, (guide[:1, :, :3, :4].clone().requires_grad_(True),))


def test_convex_kernel_keeps_the_depth_within_its_range_where_eq13_overshoots() -> None:
    """The maximum principle: every step of a convex kernel is a weighted mean (zero beyond the image), so no
    pixel goes below 0 or above the largest input; eq. 13's received weights can be negative or sum past 1
    (the overshoot of a far return inside a near object)."""
    g = torch.Generator().manual_seed(3)
    guide = torch.randn(1, 8, 16, 16, generator=g) * 3
    h = torch.rand(1, 1, 16, 16, generator=g) * 70 + 5
    for form, inside in (("convex", True), ("eq13", False)):
        w, out = normalise_affinity(guide, form), h
        for _ in range(6):
            out = propagate(w, out, h)
        assert bool((out >= 0).all() and (out <= h.max() + 1e-4).all()) is inside, form


def test_scatter_form_conserves_mass() -> None:
    """Each pixel sends W_t h to its neighbours and the weights sum to one, so with h = h0
    zero near the border the total is conserved (a gather form would not do this)."""
    w = cspn_affinity(torch.randn(1, 24, 12, 12))
    h = torch.zeros(1, 1, 12, 12)
    h[..., 2:-2, 2:-2] = torch.rand(8, 8) * 10
    out = propagate(w, h, h)
    assert torch.allclose(out.sum(), h.sum(), rtol=1e-5)
    assert not torch.allclose(out, h)


def test_bad_kernel_channels() -> None:
    with pytest.raises(ValueError, match="k\\*k channels"):
        propagate(torch.rand(1, 8, 4, 4), torch.rand(1, 1, 4, 4), torch.rand(1, 1, 4, 4))


def test_downsample_sparse_takes_nearest_valid() -> None:
    d = torch.tensor([[[[0.0, 5.0, 0.0, 0.0], [3.0, 4.0, 0.0, 0.0], [9.0, 0.0, 1.5, 2.5], [0.0, 0.0, 0.0, 0.0]]]])
    depth, mask = downsample_sparse(d)
    assert depth.tolist() == [[[[3.0, 0.0], [9.0, 1.5]]]]
    assert mask.tolist() == [[[[1.0, 0.0], [1.0, 1.0]]]]
