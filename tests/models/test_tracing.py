"""The one "is this forward being recorded?" check (models._tracing)."""

from __future__ import annotations

import torch

from semattnet.models._tracing import is_tracing
from semattnet.models.propagation.export import exporting


def test_is_tracing_only_while_recording() -> None:
    seen: list[bool] = []

    def f(x: torch.Tensor) -> torch.Tensor:
        seen.append(is_tracing())
        return x * 2

    assert not is_tracing() and not exporting()
    f(torch.ones(2))
    torch.jit.trace(f, torch.ones(2), check_trace=False)
    assert seen == [False, True]
