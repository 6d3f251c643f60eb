"""The stream: reading overlaps compute, the read-ahead is bounded, stages are timed, errors surface."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

import semattnet
from semattnet._errors import DataError
from semattnet.baselines.classical import ClassicalCompleter
from semattnet.data.frames import Frame, IndexedSource
from semattnet.inference import DepthCompleter
from semattnet.inference.backends import EngineSpec
from semattnet.inference.completer import Completion
from semattnet.inference.feed import completions
from semattnet.inference.pipeline import RunOptions, check_frames
from semattnet.inference.sinks import DepthPngSink, LatencySink
from semattnet.inference.timing import STAGES, StageTimes

SLEEP = 0.06


class SlowSource(IndexedSource):
    """``n`` tiny frames, each load sleeping ``delay`` s; records how many loads started."""

    def __init__(self, n: int, delay: float = SLEEP, fail_at: int | None = None) -> None:
        self.names = [f"f{i}" for i in range(n)]
        self.delay, self.fail_at, self.started = delay, fail_at, 0
        self.lock = threading.Lock()

    def load(self, name: str) -> Frame:
        with self.lock:
            self.started += 1
        time.sleep(self.delay)
        i = int(name[1:])
        if i == self.fail_at:
            raise DataError(f"{name}: corrupt")
        sparse = np.zeros((8, 12), np.float32)
        sparse[4, 6] = 5.0 + i
        return Frame(name, np.zeros((8, 12, 3), np.uint8), sparse, timestamp=100.0 + 0.05 * i)

    def inputs(self) -> list[Path]:
        return []


class _SlowCompleter(ClassicalCompleter):
    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        time.sleep(SLEEP)
        return Completion(np.full(sparse.shape, sparse.max(), np.float32))


slow_completer = _SlowCompleter()


def test_stream_overlaps_reading_with_compute() -> None:
    times = StageTimes()
    t0 = time.perf_counter()
    got = [f.name for f, _ in completions(SlowSource(6), slow_completer, timer=times, prefetch=2)]
    wall = time.perf_counter() - t0
    assert got == [f"f{i}" for i in range(6)]
    s = times.summary()
    assert s["frames"] == 6 and s["overlapped"]
    assert s["sum_of_stages_s"] >= 12 * SLEEP * 0.95
    assert wall < 0.8 * s["sum_of_stages_s"]  # ~7 sleeps instead of 12
    assert s["stages"]["read"]["median_ms"] >= SLEEP * 1e3 * 0.95
    assert s["stages"]["network"]["median_ms"] >= SLEEP * 1e3 * 0.95
    assert s["sensor_period_s"] == pytest.approx(0.05)  # from the frames' stamps

    seq = StageTimes()
    t0 = time.perf_counter()
    list(completions(SlowSource(6), slow_completer, timer=seq))
    assert time.perf_counter() - t0 >= 0.95 * seq.summary()["sum_of_stages_s"]  # no overlap without prefetch


@pytest.mark.parametrize("depth", [1, 3])
def test_read_ahead_is_bounded(depth: int) -> None:
    source = SlowSource(8, delay=0.005)
    ahead = []
    for taken, _ in enumerate(completions(source, slow_completer, prefetch=depth), start=1):
        time.sleep(0.03)  # a slow consumer: the reader could run far ahead if unbounded
        ahead.append(source.started - taken)
    assert max(ahead) == depth and min(ahead) >= 0


def test_background_error_surfaces_and_the_reader_stops() -> None:
    source = SlowSource(6, delay=0.005, fail_at=2)
    seen = []
    with pytest.raises(DataError, match="f2: corrupt"):
        for f, _ in completions(source, slow_completer, prefetch=2):
            seen.append(f.name)
    assert seen == ["f0", "f1"]
    assert not any(t.name == "semattnet-prefetch" for t in threading.enumerate())


def test_abandoned_stream_stops_its_reader() -> None:
    gen = completions(SlowSource(20, delay=0.005), slow_completer, prefetch=2)
    next(gen)
    gen.close()
    assert not any(t.name == "semattnet-prefetch" for t in threading.enumerate())


def test_stage_times_by_hand() -> None:
    t = StageTimes()
    for i, v in enumerate([0.010, 0.020, 0.030, 0.040, 0.100]):
        t.add(f"f{i}", "network", v)
        t.add(f"f{i}", "writing", 0.001)
        t.stamp(f"f{i}", 5.0 + 0.2 * i)
    t.wall_s = 1.0
    s = t.summary()
    assert s["stages"]["network"]["median_ms"] == pytest.approx(30.0)
    assert s["stages"]["network"]["p95_ms"] == pytest.approx(40.0 + 0.8 * 60.0)  # numpy's linear interpolation
    assert s["throughput_hz"] == pytest.approx(5.0) and s["sensor_period_s"] == pytest.approx(0.2)
    assert s["realtime_factor"] == pytest.approx(1.0)
    assert s["per_frame_median_ms"] == pytest.approx(31.0)
    table = t.table()
    assert "network" in table and "30.0" in table and "88.0" in table and "5.0 Hz" in table and "keeps up" in table
    assert set(s["stages"]) == set(STAGES) and "note" in s["stages"]["read"]


def test_nested_stage_is_subtracted() -> None:
    t = StageTimes()
    with t.time("a", "network"):
        time.sleep(0.02)
        with t.time("a", "propagation"):
            time.sleep(0.03)
    assert t.times["a"]["propagation"] >= 0.03 and 0.02 <= t.times["a"]["network"] < 0.03


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_depth_completer_stream_times_network_and_propagation() -> None:
    import torch

    torch.manual_seed(0)
    completer = DepthCompleter(semattnet.build_model("semattnet", width=0.125), EngineSpec(device="cpu"))
    source = SlowSource(3, delay=0.0)
    times = StageTimes()
    got = list(completer.stream(source, timer=times, prefetch=2))
    for frame, completion in got:  # the same result as a direct call (fallback semantic map filled)
        direct = completer(frame.rgb, frame.sparse, frame.semantic)
        assert np.array_equal(completion.depth, direct.depth)
    s = times.summary()["stages"]
    assert s["network"]["frames"] == 3 and s["propagation"]["frames"] == 3
    assert "propagation" not in vars(completer.engine(None).net)  # the model's own method again


def test_complete_frames_writes_latency_json(tmp_path: Path) -> None:
    import json

    times = StageTimes()
    sinks = [DepthPngSink(), LatencySink(timer=times)]
    plan = check_frames(SlowSource(3, delay=0.0), sinks, tmp_path / "out", options=RunOptions(prefetch=2))
    plan.run(slow_completer, timer=times, log=lambda _: None)
    doc = json.loads((tmp_path / "out" / "latency.json").read_text())
    assert doc["frames"] == 3 and doc["stages"]["writing"]["frames"] == 3 and doc["overlapped"]
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == ["f0.png", "f1.png", "f2.png", "frames.json", "latency.json"]
