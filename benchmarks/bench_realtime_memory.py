"""Memory of a long ``--realtime`` replay: the resident set size over a few hundred frames.

Writes an MCAP bag of ``--frames`` copies of the bundled KITTI raw frame (1242x375 image and its 120k-point
Velodyne scan) stamped at the sensor's 10 Hz, then replays it through the one frame loop at the recorded
rate, ``--speed`` times faster (``RunOptions(realtime=SPEED)`` of the plan; the classical completion, depth
PNGs written) while a thread samples the process's RSS every 50 ms. Prints the RSS after the first 10 % of
the frames, at the middle and at the end, its peak, the frames done and dropped, and the most frames that
waited for the completer, with the CPU::

    python benchmarks/bench_realtime_memory.py --frames 1200 --out /tmp/rt-bench
"""

from __future__ import annotations

import argparse
import shutil
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DRIVE = REPO / "tests/data/kitti_sample/kitti_raw/2011_09_26/2011_09_26_drive_0035_sync"


def rss_mib() -> float:
    """This process's resident set size, MiB (``/proc/self/statm``)."""
    import os

    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def write_bag(path: Path, frames: int) -> Path:
    """``frames`` copies of the bundled KITTI frame at 10 Hz (scan 3 ms after its image), MCAP."""
    from semattnet.data.kitti.raw import RawDrive
    from semattnet.robotics.bags import SensorRecord, write_sensor_bag

    raw = RawDrive(DRIVE, 2).frame(RawDrive(DRIVE, 2).names_for(None)[0])
    t0 = 1_700_000_000 * 10**9
    records = (SensorRecord(raw.image, raw.points, t0 + i * 10**8, t0 + i * 10**8 + 3 * 10**6) for i in range(frames))
    return write_sensor_bag(path, records, raw.calib, fmt="mcap", overwrite=True).path


def replay(bag: Path, out: Path, speed: float = 1.0) -> dict[str, object]:
    """The bag at its recorded rate through the loop, RSS sampled meanwhile."""
    from semattnet.baselines import ClassicalCompleter
    from semattnet.inference.pipeline import RunOptions, check_frames
    from semattnet.inference.sinks import DepthPngSink, LatencySink
    from semattnet.inference.timing import StageTimes
    from semattnet.robotics import BagSource
    from semattnet.robotics.bags import BagTopics

    topics = BagTopics()
    source = BagSource(bag, topics.image, topics.points)
    samples: list[tuple[int, float]] = []
    stop, done = threading.Event(), [0]

    def sample() -> None:
        while not stop.wait(0.05):
            samples.append((done[0], rss_mib()))

    timer = StageTimes()
    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    plan = check_frames(source, [DepthPngSink(), LatencySink(timer=timer)], out, options=RunOptions(realtime=speed))
    run = plan.run(ClassicalCompleter(), timer=timer, log=lambda line: done.__setitem__(0, done[0] + 1))
    stop.set()
    thread.join()
    n = len(source.names)
    at = {q: next((r for k, r in samples if k >= q * n), samples[-1][1]) for q in (0.1, 0.5, 1.0)}
    return {
        "frames": n,
        "counts": run.counts,
        "queue_most": timer.queue_most,
        "rss_10pct": at[0.1],
        "rss_50pct": at[0.5],
        "rss_end": at[1.0],
        "rss_peak": max(r for _, r in samples),
    }


def main() -> None:
    from semattnet.inference.timing import cpu_name

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--out", type=Path, default=Path("rt-bench"))
    parser.add_argument("--speed", type=float, default=1.0, help="replay this many times faster than recorded")
    args = parser.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    t = time.perf_counter()
    bag = write_bag(args.out / "replay.mcap", args.frames)
    print(f"bag of {args.frames} frames written in {time.perf_counter() - t:.1f} s")
    r = replay(bag, args.out / "pred", args.speed)
    print(f"CPU: {cpu_name()}; numpy {np.__version__}")
    print(
        f"{r['frames']} frames at 10 Hz x {args.speed:g}: {r['counts']['done']} done, {r['counts']['dropped']} "
        f"dropped; at most {r['queue_most']} frame(s) waited"
    )
    print(
        f"RSS MiB: after 10 % {r['rss_10pct']:.0f}, at 50 % {r['rss_50pct']:.0f}, at the end "
        f"{r['rss_end']:.0f}, peak {r['rss_peak']:.0f}"
    )


if __name__ == "__main__":
    main()
