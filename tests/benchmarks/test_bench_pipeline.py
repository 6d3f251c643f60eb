"""benchmarks/bench_pipeline.py at a tiny size: the synthetic raw drive it writes, and its report (no time asserted)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.benchmarks._scripts import load_script


def test_the_drive_is_resized_with_its_calibration(tmp_path: Path) -> None:
    from semattnet.data.sources import RawDriveSource

    bench = load_script("bench_pipeline")
    native = RawDriveSource(bench.make_drive(tmp_path / "a", 1, (375, 1242)))
    half = RawDriveSource(bench.make_drive(tmp_path / "b", 3, (188, 621)))
    assert half.names == ["0000000000", "0000000001", "0000000002"]
    a, b = native.load(native.names[0]), half.load(half.names[-1])
    assert b.rgb.shape == (188, 621, 3) and b.sparse.shape == (188, 621)
    np.testing.assert_allclose(b.K[:2], a.K[:2] * np.array([[0.5], [188 / 375]]), rtol=1e-6)
    # the same scan lands in the same places: about as many pixels (some merge), the same depths
    assert 0.5 * np.count_nonzero(a.sparse) < np.count_nonzero(b.sparse) <= np.count_nonzero(a.sparse)
    assert abs(np.median(b.sparse[b.sparse > 0]) - np.median(a.sparse[a.sparse > 0])) < 1.0


@pytest.mark.filterwarnings("ignore::UserWarning")  # random weights: holes and clamps, the fallback semantic map
def test_bench_pipeline_reports_both_rates_and_the_stage_table(tmp_path: Path) -> None:
    bench = load_script("bench_pipeline")
    out = tmp_path / "r.json"
    args = ["--frames", "2", "--size", "32x96", "--width", "0.125", "--rounds", "1", "--json", str(out)]
    assert bench.main(args) == 0
    r = json.loads(out.read_text())
    assert r["frames"] == 2 and r["size"] == [32, 96] and r["cpu"] and r["prefetch"] == 2
    assert r["fps_network"] > 0 and r["fps_pipeline"] > 0 and r["check_s"] >= 0
    assert r["overhead"] == pytest.approx(1 - r["fps_pipeline"] / r["fps_network"])
    assert r["latency"]["frames"] == 2 and r["latency"]["overlapped"]
    for stage in ("read", "network", "writing"):
        assert r["stages"][stage]["frames"] == 2, stage
