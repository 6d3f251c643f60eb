"""benchmarks/bench_realtime.py at a tiny size: the 10 Hz recording it writes and its report (no time asserted)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.benchmarks._scripts import load_script


@pytest.mark.slow  # ~2 s: a bag written and replayed through predict (imports and first calls, mostly)
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_bench_realtime_writes_a_10_hz_bag_and_reports_the_counts_and_stages(tmp_path: Path) -> None:
    from semattnet.robotics import BagSource
    from semattnet.robotics.bags import BagTopics

    bench = load_script("bench_realtime")
    out = tmp_path / "r.json"
    args = [
        "--frames",
        "3",
        "--size",
        "32x96",
        "--scenes",
        "2",
        "--speed",
        "10",
        "--warmup",
        "1",
        "--serial",
        "--out",
        str(tmp_path / "w"),
        "--json",
        str(out),
    ]
    assert bench.main(args) == 0
    topics = BagTopics()
    source = BagSource(tmp_path / "w" / "recording.mcap", topics.image, topics.points)
    frames = [source.load(n) for n in source.names]
    assert len(frames) == 3 and frames[0].rgb.shape == (32, 96, 3) and all(f.sparse.any() for f in frames)
    assert (frames[0].rgb == frames[2].rgb).all() and not (frames[0].rgb == frames[1].rgb).all()  # 2 scenes, cycled
    stamps = source.info.stamps_ns
    assert stamps is not None and np.diff(stamps).tolist() == [bench.PERIOD_NS] * 2

    doc = json.loads(out.read_text())
    assert doc["size"] == [32, 96] and doc["cpu"] and doc["method"] == "classical" and doc["warmup"] == 1
    for name, writer in (("pipelined", "the writer thread"), ("serial", None)):
        r = doc[name]
        assert r["frames_fed"] == 3 and r["completed"] >= 1 and r["completed"] + r["dropped"] + r["skipped"] == 3
        assert r["exit_code"] == (4 if r["dropped"] else 0) and r["latency"]["not_done"]["dropped"] == r["dropped"]
        stages = r["latency"]["stages"]
        assert stages["network"]["frames"] == r["completed"] and "beside" not in stages["network"]
        assert stages["writing"].get("beside") == writer and stages["read"]["beside"] == "the sensor thread"
