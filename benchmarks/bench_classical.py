"""The classical completion and the LiDAR distance transform: the PyTorch path against the C++ kernel.

    python benchmarks/bench_classical.py [--sizes 352x1216,375x1242] [--threads 1,2] [--runs 15] [--json out.json]

Per size and thread count: ``complete_classical``, ``classical_fill_step`` and ``lidar_distance``, each through
the PyTorch path (``impl="pytorch"``) and the kernel (``impl="auto"``), taken in turns (one call of each, then
again), the median of ``--runs`` calls and the ratio. The sparse map: the bundled KITTI frame's own scan
(tests/data/kitti_sample; cropped to the size's bottom centre, as the KITTI benchmark crops it) where present,
else random points at KITTI's density (4 %). The results must be equal: checked on every size before timing.
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import torch

from semattnet._utils.cpu import cpu_summary
from semattnet.models import anchor_kernel
from semattnet.models.anchor import classical_fill_step, complete_classical
from semattnet.models.uncertainty import lidar_distance

SAMPLE = Path(__file__).resolve().parents[1] / "tests" / "data" / "kitti_sample"
DENSITY = 0.04  # KITTI's share of measured pixels in a 375x1242 frame


def sparse_map(h: int, w: int, seed: int = 0) -> tuple[torch.Tensor, str]:
    """(1, 1, h, w) sparse depth and where it comes from: the KITTI frame's bottom centre, else random points."""
    try:
        from semattnet.evaluation.zero_shot import real_frames

        frame = torch.as_tensor(real_frames(SAMPLE)[0].sparse).float()
        if frame.shape[0] >= h and frame.shape[1] >= w:
            x0 = (frame.shape[1] - w) // 2
            return frame[-h:, x0 : x0 + w].contiguous()[None, None], "KITTI frame"
    except Exception:  # no sample: random points
        pass
    g = torch.Generator().manual_seed(seed)
    depth = 1 + 79 * torch.rand(1, 1, h, w, generator=g)
    return depth * (torch.rand(1, 1, h, w, generator=g) < DENSITY), f"random {DENSITY:.0%}"


def in_turns(calls: Sequence[Callable[[], object]], runs: int) -> list[float]:
    """The median time (ms) of each call, the calls taken in turns ``runs`` times (after one warm-up each)."""
    for call in calls:
        call()
    times: list[list[float]] = [[] for _ in calls]
    for _ in range(runs):
        for call, kept in zip(calls, times, strict=True):
            start = time.perf_counter()
            call()
            kept.append(time.perf_counter() - start)
    return [statistics.median(t) * 1e3 for t in times]


def check_equal(sparse: torch.Tensor) -> None:
    """The kernel's results against the PyTorch path's (medians and copies to the bit, the Gaussian too)."""
    torch.testing.assert_close(complete_classical(sparse), complete_classical(sparse, impl="pytorch"), atol=0, rtol=0)
    assert torch.equal(classical_fill_step(sparse), classical_fill_step(sparse, impl="pytorch"))
    assert torch.equal(lidar_distance(sparse), lidar_distance(sparse, impl="pytorch"))


def measure(size: tuple[int, int], threads: int, runs: int) -> list[dict[str, object]]:
    """One row per function at one size and thread count."""
    torch.set_num_threads(threads)
    sparse, source = sparse_map(*size)
    check_equal(sparse)
    functions: dict[str, Callable[..., torch.Tensor]] = {
        "complete_classical": complete_classical,
        "classical_fill_step": classical_fill_step,
        "lidar_distance": lidar_distance,
    }
    rows = []
    for name, fn in functions.items():
        ms = in_turns([functools.partial(fn, sparse, impl="pytorch"), functools.partial(fn, sparse)], runs)
        rows.append(
            {
                "function": name,
                "size": f"{size[0]}x{size[1]}",
                "threads": threads,
                "sparse": source,
                "pytorch_ms": ms[0],
                "kernel_ms": ms[1],
                "ratio": ms[0] / ms[1],
            }
        )
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="352x1216,375x1242", help="HxW, comma-separated")
    parser.add_argument("--threads", default="1,2", help="thread counts, comma-separated")
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--json", type=Path, help="write the rows here")
    args = parser.parse_args(argv)
    if not anchor_kernel.available():
        print(f"the kernel is unavailable ({anchor_kernel.KERNEL.failed}): nothing to compare", file=sys.stderr)
        return 1
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    print(cpu_summary())
    print(f"{'function':<20} {'size':>9} {'thr':>3} {'pytorch ms':>11} {'kernel ms':>10} {'ratio':>6}  sparse")
    rows = []
    for size in sizes:
        for threads in (int(t) for t in args.threads.split(",")):
            for r in measure((size[0], size[1]), threads, args.runs):  # said as measured
                rows.append(r)
                print(
                    f"{r['function']:<20} {r['size']:>9} {r['threads']:>3} {r['pytorch_ms']:>11.2f} "
                    f"{r['kernel_ms']:>10.2f} {r['ratio']:>6.1f}  {r['sparse']}",
                    flush=True,
                )
    if args.json:
        args.json.write_text(json.dumps({"cpu": cpu_summary(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
