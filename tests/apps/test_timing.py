"""The timing machinery of ``semattnet bench`` (apps.timing), checked against hand-computed values."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from semattnet.apps import benchmark
from semattnet.apps.timing import count_macs, interleaved, peak_memory, timeit


class _Net(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.conv = nn.Conv2d(3, 4, 3, padding=1)
        self.fc = nn.Linear(5, 2)

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.conv(x), self.fc(y)


def test_count_macs_by_hand() -> None:
    # conv: 4 x 8 x 8 outputs, each 3 x 3 x 3 MACs; linear: 7 x 2 outputs, each 5 MACs.
    macs = count_macs(_Net(), {"x": torch.zeros(1, 3, 8, 8), "y": torch.zeros(7, 5)})
    assert macs == pytest.approx((4 * 8 * 8 * 27 + 7 * 2 * 5) / 1e9)


def test_timeit_and_interleaved_run_what_they_time() -> None:
    calls: list[str] = []
    cpu = torch.device("cpu")
    assert timeit(lambda: calls.append("a"), cpu, repeats=3, warmup=2) >= 0
    assert calls == ["a"] * 5
    calls.clear()
    times = interleaved({"a": lambda: calls.append("a"), "b": lambda: calls.append("b")}, cpu, repeats=2)
    assert set(times) == {"a", "b"} and calls == ["a", "b", "a", "b"]
    with peak_memory(cpu) as mem:
        torch.zeros(1000)
    assert "peak_mib" in mem


def test_benchmark_keeps_the_timing_names() -> None:
    for name in ("timeit", "interleaved", "peak_memory", "count_macs", "conv_peak_gflops", "fast_mode_dtype"):
        assert name in benchmark.__all__ and callable(getattr(benchmark, name))
