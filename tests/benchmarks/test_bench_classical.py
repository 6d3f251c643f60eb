"""benchmarks/bench_classical.py at a tiny size: its rows (no time asserted)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from semattnet.models import anchor_kernel
from tests.benchmarks._scripts import load_script


@pytest.mark.skipif(not anchor_kernel.available(), reason="no C++ toolchain for the classical-completion kernel")
def test_bench_classical_compares_both_paths_on_each_function(tmp_path: Path) -> None:
    bench = load_script("bench_classical")
    out = tmp_path / "b.json"
    assert bench.main(["--sizes", "24x40", "--threads", "1", "--runs", "1", "--json", str(out)]) == 0
    saved = json.loads(out.read_text())
    assert saved["cpu"] and [r["function"] for r in saved["rows"]] == [
        "complete_classical",
        "classical_fill_step",
        "lidar_distance",
    ]
    assert all(r["pytorch_ms"] > 0 and r["kernel_ms"] > 0 and r["size"] == "24x40" for r in saved["rows"])
