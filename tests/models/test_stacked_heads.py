"""stacked_heads: several conv-headed Sequentials on one input as one convolution, the same function."""

from __future__ import annotations

import copy

import torch
from torch import nn

from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.layers import convbn, stacked_heads


def _heads(seed: int = 0) -> nn.ModuleList:
    torch.manual_seed(seed)
    heads = nn.ModuleList([convbn(6, n) for n in (3, 1, 8)])
    for h in heads:  # BatchNorm statistics that are not the identity
        h[1].running_mean.uniform_(-0.5, 0.5)
        h[1].running_var.uniform_(0.5, 2.0)
        h[1].weight.data.uniform_(0.5, 1.5)
        h[1].bias.data.uniform_(-0.2, 0.2)
    return heads


def test_training_matches_the_heads_one_by_one_outputs_gradients_and_running_stats() -> None:
    ours, ref = _heads(), _heads()
    x = torch.randn(2, 6, 9, 11)
    got = stacked_heads(x, list(ours))
    want = torch.cat([h(x) for h in ref], dim=1)
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    (got * torch.arange(got.numel()).view_as(got)).sum().backward()
    (want * torch.arange(want.numel()).view_as(want)).sum().backward()
    for a, b in zip(ours.parameters(), ref.parameters(), strict=True):
        torch.testing.assert_close(a.grad, b.grad, rtol=1e-4, atol=1e-4)
    for a, b in zip(ours.buffers(), ref.buffers(), strict=True):
        torch.testing.assert_close(a, b)  # each head's BatchNorm saw its own channels


def test_eval_and_folded_match_and_other_geometries_fall_back() -> None:
    heads = _heads().eval()
    x = torch.randn(1, 6, 8, 8)
    want = torch.cat([h(x) for h in heads], dim=1)
    folded = fold_batchnorm(copy.deepcopy(heads))
    for got in (stacked_heads(x, list(heads)), stacked_heads(x, list(folded))):
        torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    mixed = [*heads, convbn(6, 2, kernel_size=1, padding=0).eval()]  # another geometry: one by one
    outs = stacked_heads(x, mixed)
    assert outs.shape[1] == 3 + 1 + 8 + 2
    torch.testing.assert_close(outs[:, -2:], mixed[-1](x))
