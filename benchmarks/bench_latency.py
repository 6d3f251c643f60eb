"""Latency of the full model and of the propagation at 352x1216, against the pad-and-sum
propagation pattern of the authors' code, in one process. Prints medians and ratios.

    python benchmarks/bench_latency.py [--size 352x1216] [--repeats 3] [--threads N]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import semattnet
from naive_reference import pad_and_sum_propagate
from semattnet import refinement
from semattnet.propagation import cspn_affinity, propagate_shifted, shift_affinity


def timeit(fn, repeats: int, warmup: int = 1) -> float:  # type: ignore[no-untyped-def]
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        t = time.perf_counter()
        fn()
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


class _NaivePropagation:
    """Swap the model's propagation for the pad-and-sum pattern (weights shifted per step)."""

    def __enter__(self) -> None:
        self._shift, self._step = refinement.shift_affinity, refinement.propagate_shifted
        refinement.shift_affinity = lambda a, dilation=1: a
        refinement.propagate_shifted = pad_and_sum_propagate

    def __exit__(self, *exc: object) -> None:
        refinement.shift_affinity, refinement.propagate_shifted = self._shift, self._step


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="352x1216")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=0, help="torch threads (0 = default)")
    p.add_argument("--skip-model", action="store_true", help="only the propagation")
    args = p.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    h, w = (int(v) for v in args.size.split("x"))
    dev = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    print(f"device {dev}, torch {torch.__version__}, {torch.get_num_threads()} threads, size {h}x{w}")

    # One propagation stage as the model runs it: 6 steps for each of k = 3, 5, 7 at full size.
    g = torch.Generator().manual_seed(0)
    affs = [cspn_affinity(torch.randn(1, k * k - 1, h, w, generator=g)).to(dev) for k in (3, 5, 7)]
    d = (torch.rand(1, 1, h, w, generator=g) * 80).to(dev)

    def stage(prepare, step) -> torch.Tensor:  # type: ignore[no-untyped-def]
        out = d
        for a in affs:
            kernel = prepare(a)  # ours: shift the fixed kernel once per stage
            x = d
            for _ in range(6):
                x = step(kernel, x, d)
            out = out + x
        return out

    ours_stage = lambda: stage(shift_affinity, propagate_shifted)  # noqa: E731
    naive_stage = lambda: stage(lambda a: a, pad_and_sum_propagate)  # noqa: E731
    with torch.inference_mode():
        ours, naive = ours_stage(), naive_stage()
        err = float((ours - naive).abs().max() / naive.abs().max())
        t_ours = timeit(ours_stage, args.repeats)
        t_naive = timeit(naive_stage, args.repeats)
    print(f"propagation stage (18 steps): ours {t_ours * 1e3:8.1f} ms   pad-and-sum {t_naive * 1e3:8.1f} ms   "
          f"speed-up x{t_naive / t_ours:.1f}   max rel. diff {err:.1e}")  # fmt: skip

    if args.skip_model:
        return
    model = semattnet.build_model("semattnet").to(dev).eval()
    x = {"rgb": torch.rand(1, 3, h, w, device=dev) * 255, "semantic": torch.rand(1, 3, h, w, device=dev) * 255,
         "sparse": (torch.rand(1, 1, h, w, device=dev) < 0.05) * torch.rand(1, 1, h, w, device=dev) * 80}  # fmt: skip
    with torch.inference_mode():
        t_model = timeit(lambda: model(**x), args.repeats)
        ref = model(**x).refined_depth
        with _NaivePropagation():
            t_model_naive = timeit(lambda: model(**x), args.repeats)
            naive_out = model(**x).refined_depth
    err = float((ref - naive_out).abs().max() / naive_out.abs().max())
    print(f"full model forward:           ours {t_model:8.2f} s    naive prop. {t_model_naive:8.2f} s    "
          f"speed-up x{t_model_naive / t_model:.2f}   max rel. diff {err:.1e}")  # fmt: skip


if __name__ == "__main__":
    main()
