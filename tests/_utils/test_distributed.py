"""The training helpers of ``semattnet._utils.distributed`` in one process (torchrun runs: the trainer's and adapt's
tests)."""

from __future__ import annotations

import torch

from semattnet._utils.distributed import check_in_sync, rank_seed


def test_each_rank_draws_its_own_stream_and_rank_0_the_seed_itself() -> None:
    assert rank_seed(7, 0) == 7
    draws = [torch.rand(4, generator=torch.Generator().manual_seed(rank_seed(7, r))) for r in range(4)]
    assert all(not torch.equal(draws[i], draws[j]) for i in range(4) for j in range(i))


def test_one_process_is_in_sync_with_itself() -> None:
    model = torch.nn.Linear(2, 1)
    assert check_in_sync(model) == sum(float(p.detach().double().sum()) for p in model.parameters())
