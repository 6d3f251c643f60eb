"""Per-stage times of the frame loop: :class:`StageTimes` (seconds per stage per frame, the wall time, the
sensor period) and what ``latency.json`` holds (:class:`LatencySummary`)."""

from __future__ import annotations

import json
import platform
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TypedDict

import numpy as np

__all__ = [
    "DEFAULT_SENSOR_PERIOD_S",
    "GAP_PERIODS",
    "LATENCY_FILE",
    "MAX_WAIT_S",
    "STAGES",
    "LatencySummary",
    "StageSummary",
    "StageTally",
    "StageTimes",
    "cpu_name",
]

#: The stages timed, in order.
STAGES = ("read", "projection", "segmentation", "network", "propagation", "writing")
_LABELS = {"read": "read/decode", "writing": "write/publish"}
#: The sensor period assumed when the frames' stamps cannot say (a 10 Hz LiDAR), seconds.
DEFAULT_SENSOR_PERIOD_S = 0.1
#: ``--realtime``: a gap between two frames longer than this many sensor periods (their median so far) is skipped.
GAP_PERIODS = 5
#: ``--realtime``: the longest wait for one frame, seconds (a longer one is skipped as well).
MAX_WAIT_S = 60.0
#: Where ``semattnet predict`` writes the table, in its ``--out``.
LATENCY_FILE = "latency.json"


class StageSummary(TypedDict, total=False):
    """One stage of :meth:`StageTimes.summary`: ``median_ms``, ``p95_ms`` and ``frames``, or ``note`` (not run);
    ``beside``: the thread it runs in beside the network (absent: on the loop's serial path)."""

    median_ms: float
    p95_ms: float
    frames: int
    note: str
    beside: str


class LatencySummary(TypedDict):
    """:meth:`StageTimes.summary` (what ``latency.json`` holds)."""

    frames: int
    stages: dict[str, StageSummary]
    sum_of_stages_s: float
    wall_s: float
    overlapped: bool
    per_frame_median_ms: float
    serial_median_ms: float
    write_waited_s: float
    throughput_hz: float
    sensor_period_s: float
    realtime_factor: float
    not_done: dict[str, int]
    queue_most: int | None
    gaps_skipped: int
    cpu: str


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :mod:`platform` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


class StageTimes:
    """Seconds per stage per frame (thread-safe), the loop's wall time and the sensor period.

    A stage timed inside another (``propagation`` inside ``network``) is subtracted from the outer one, so
    the stages add up to the time spent. ``notes``: stage -> why it has no times (shown in the table).
    ``beside``: stage -> the thread it runs in beside the network (the reading in the reader's, the writing in
    the writer's); the other stages are the serial path, which bounds the frames per second.
    ``write_waited_s``: how long the loop waited for the writer (it ran behind by as many frames as allowed).
    """

    def __init__(self) -> None:
        self.times: dict[str, dict[str, float]] = {}
        self.stamps: dict[str, float] = {}
        self.notes: dict[str, str] = {}
        self.beside: dict[str, str] = {}
        self.write_waited_s = 0.0
        self.wall_s = 0.0
        self.overlapped = False
        self.queue_most: int | None = None  # --realtime: the most frames waiting for the completer at once
        self.not_done: dict[str, int] = {}  # frames skipped / dropped, by status (the loop sets it)
        self.gaps_skipped = 0  # --realtime: gaps between frames not waited for (too long)
        self.longest_gap_s = 0.0  # ... the longest of them, sensor seconds
        self._lock = threading.Lock()
        self._local = threading.local()
        self._start: float | None = None

    def add(self, name: str, stage: str, seconds: float) -> None:
        with self._lock:
            per = self.times.setdefault(name, {})
            per[stage] = per.get(stage, 0.0) + float(seconds)

    @contextmanager
    def time(self, name: str, stage: str) -> Iterator[None]:
        """Time the block as ``stage`` of frame ``name`` (less the stages timed inside it, same thread)."""
        stack = self._local.__dict__.setdefault("stack", [])
        stack.append(0.0)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            total = time.perf_counter() - t0
            inner = stack.pop()
            if stack:
                stack[-1] += total
            self.add(name, stage, total - inner)

    def share(self, name: str, names: Sequence[str], stages: Sequence[str]) -> None:
        """Share frame ``name``'s times of ``stages`` evenly over ``names`` (frames completed in one call)."""
        with self._lock:
            first = self.times.setdefault(name, {})
            part = {s: first[s] / len(names) for s in stages if s in first}
            for other in names:
                self.times.setdefault(other, {}).update(part)

    def discard(self, name: str) -> None:
        """Forget frame ``name``'s times (a frame that was not completed)."""
        with self._lock:
            self.times.pop(name, None)

    def settle(self, name: str) -> dict[str, float]:
        """Frame ``name``'s seconds per stage, forgotten here (a live run hands each frame to a
        :class:`StageTally` this way, so its memory stays the same however long it runs)."""
        with self._lock:
            self.stamps.pop(name, None)
            return self.times.pop(name, {})

    def stamp(self, name: str, seconds: float | None) -> None:
        """Record frame ``name``'s sensor time (seconds), for the sensor period."""
        if seconds is not None:
            with self._lock:
                self.stamps[name] = float(seconds)

    def begin(self) -> None:
        self._start = time.perf_counter()

    def end(self) -> None:
        if self._start is not None:
            self.wall_s += time.perf_counter() - self._start
            self._start = None

    @property
    def frames(self) -> int:
        return len(self.times)

    @property
    def sensor_period_s(self) -> float:
        """Median spacing of the frames' distinct stamps, else :data:`DEFAULT_SENSOR_PERIOD_S`."""
        s = np.unique(np.array(list(self.stamps.values()), dtype=np.float64))
        d = np.diff(s)
        return float(np.median(d)) if len(d) and np.median(d) > 0 else DEFAULT_SENSOR_PERIOD_S

    def stage(self, stage: str) -> np.ndarray:
        """Seconds of ``stage``, one per frame that ran it."""
        with self._lock:
            return np.array([t[stage] for t in self.times.values() if stage in t], dtype=np.float64)

    def _stage_summary(self, stage: str) -> StageSummary:
        v = self.stage(stage)
        row: StageSummary = (
            {"median_ms": 1e3 * float(np.median(v)), "p95_ms": 1e3 * float(np.percentile(v, 95)), "frames": len(v)}
            if len(v)
            else {"note": self.notes.get(stage, "not run")}
        )
        if stage in self.beside and len(v):
            row["beside"] = self.beside[stage]
        return row

    def summary(self) -> LatencySummary:
        """Median and p95 per stage (ms), the sum of medians, wall time, throughput and the sensor period."""
        stages = {s: self._stage_summary(s) for s in STAGES}
        with self._lock:
            per_frame = [sum(t.values()) for t in self.times.values()]
            serial = [sum(v for k, v in t.items() if k not in self.beside) for t in self.times.values()]
        period = self.sensor_period_s
        fps = self.frames / self.wall_s if self.wall_s > 0 else 0.0
        return {
            "frames": self.frames,
            "stages": stages,
            "sum_of_stages_s": float(sum(per_frame)),
            "wall_s": self.wall_s,
            "overlapped": self.overlapped,
            "per_frame_median_ms": 1e3 * float(np.median(per_frame)) if per_frame else 0.0,
            "serial_median_ms": 1e3 * float(np.median(serial)) if serial else 0.0,
            "write_waited_s": self.write_waited_s,
            "throughput_hz": fps,
            "sensor_period_s": period,
            "realtime_factor": fps * period,
            "not_done": dict(self.not_done),
            "queue_most": self.queue_most,
            "gaps_skipped": self.gaps_skipped,
            "cpu": cpu_name(),
        }

    def table(self) -> str:
        """The per-stage latency table (what ``semattnet predict`` prints)."""
        s = self.summary()
        rows = [f"{'stage':<14}{'median ms':>11}{'p95 ms':>10}  runs"]
        for stage, r in s["stages"].items():
            label = _LABELS.get(stage, stage)
            if "median_ms" in r and "p95_ms" in r:
                runs = f"beside the network ({r['beside']})" if "beside" in r else "serial"
                rows.append(f"{label:<14}{r['median_ms']:>11.1f}{r['p95_ms']:>10.1f}  {runs}")
            else:
                rows.append(f"{label:<14}{'-':>11}{'-':>10}  ({r.get('note', '')})")
        period = s["sensor_period_s"]
        verdict = "keeps up" if s["realtime_factor"] >= 1 else "falls behind"
        rows.append(f"{'per frame':<14}{s['per_frame_median_ms']:>11.1f}")
        if any("beside" in r for r in s["stages"].values()):
            rows.append(f"{'serial path':<14}{s['serial_median_ms']:>11.1f}  (what bounds the frames/s)")
        if s["write_waited_s"] > 0.0005:
            rows.append(f"the loop waited {s['write_waited_s']:.2f} s in all for the writer (it fell behind)")
        rows.append(
            f"{s['frames']} frame(s) in {s['wall_s']:.2f} s{' (read ahead)' if s['overlapped'] else ''}: "
            f"{s['throughput_hz']:.2f} frames/s against a sensor period of {1e3 * period:.1f} ms "
            f"({1 / period:.1f} Hz): {s['realtime_factor']:.2g}x real time, {verdict}"
        )
        if any(s["not_done"].values()):
            held = f"; at most {s['queue_most']} frame(s) waited" if s["queue_most"] is not None else ""
            rows.append("not completed: " + ", ".join(f"{n} {k}" for k, n in s["not_done"].items() if n) + held)
        if self.gaps_skipped:
            rows.append(
                f"--realtime skipped {self.gaps_skipped} gap(s) between frames too long to wait for (over "
                f"{GAP_PERIODS} sensor periods or {MAX_WAIT_S:g} s; the longest {self.longest_gap_s:.3g} s)"
            )
        return "\n".join(rows)

    def to_json(self) -> str:
        return json.dumps(self.summary(), indent=2) + "\n"


class StageTally:
    """Count, sum and maximum per stage of the frames settled so far (:meth:`StageTimes.settle`): since the last
    :meth:`line` and in total, in constant memory (a live node's report lines)."""

    def __init__(self) -> None:
        self.period: dict[str, list[float]] = {}  # stage -> [count, sum ms, max ms]
        self.total: dict[str, list[float]] = {}

    def add(self, seconds: dict[str, float]) -> None:
        """One frame's seconds per stage."""
        for stage, s in seconds.items():
            for table in (self.period, self.total):
                c = table.setdefault(stage, [0.0, 0.0, 0.0])
                c[0], c[1], c[2] = c[0] + 1, c[1] + 1e3 * s, max(c[2], 1e3 * s)

    def line(self, total: bool = False) -> str:
        """``ms mean/max: stage mean/max, ...`` in :data:`STAGES` order, since the last line (``total``: of all),
        which starts a new period."""
        table = self.total if total else self.period
        parts = [f"{_LABELS.get(s, s)} {c[1] / c[0]:.1f}/{c[2]:.1f}" for s in STAGES if (c := table.get(s)) and c[0]]
        if not total:
            self.period = {}
        return "ms mean/max: " + (", ".join(parts) or "none yet")
