"""Whole-forward time of the real-time variants as ratios against the width-1/8 paper model, taken in turns.

    python benchmarks/bench_rt.py [--size 352x1216] [--repeats 5] [--models semattnet_rt_s,semattnet_rt_m]
                                  [--channels-last] [--json out.json]

Every model is built with random weights, BatchNorm folded (:func:`~semattnet.models.bn_folding.fold_batchnorm`)
and run in float32 under ``torch.inference_mode`` on one random frame (5 % LiDAR density), the network and the
propagation together. The models run in turns within one process, ``--repeats`` rounds, so a machine shared
with other jobs slows all of them alike: the **ratio** to the paper model at width 1/8 (median over rounds)
is the figure to read; the milliseconds are the medians of this run. The CPU is printed with its ISA flags
(:func:`semattnet._utils.cpu.cpu_summary`).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import torch

import semattnet
from semattnet._utils.cpu import cpu_summary
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.macs import count_macs

REFERENCE = ("semattnet", {"width": 0.125})


def cpu_name() -> str:
    """The CPU named: model, threads, torch's SIMD level and its notable ISA flags (avx2, avx512*, amx*)."""
    return cpu_summary()


def frame(size: tuple[int, int], seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    h, w = size
    sparse = (torch.rand(1, 1, h, w, generator=g) < 0.05) * torch.rand(1, 1, h, w, generator=g) * 80
    return {
        "rgb": torch.rand(1, 3, h, w, generator=g) * 255,
        "semantic": torch.rand(1, 3, h, w, generator=g) * 255,
        "sparse": sparse,
    }


def main(argv: list[str] | None = None) -> dict[str, dict[str, float]]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="352x1216")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--models", default="semattnet_rt_s,semattnet_rt_m")
    ap.add_argument("--channels-last", action="store_true")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    assert len(size) == 2
    x = frame(size)  # type: ignore[arg-type]
    names = ["paper@1/8", *args.models.split(",")]
    nets = {"paper@1/8": semattnet.build_model(REFERENCE[0], **REFERENCE[1])}
    nets.update({n: semattnet.build_model(n) for n in names[1:]})
    info = {
        n: {"gmac": count_macs(net.eval(), x), "params": sum(p.numel() for p in net.parameters())}
        for n, net in nets.items()
    }
    fast = {n: fold_batchnorm(net) for n, net in nets.items()}
    if args.channels_last:
        fast = {n: net.to(memory_format=torch.channels_last) for n, net in fast.items()}
    times: dict[str, list[float]] = {n: [] for n in names}
    with torch.inference_mode():
        for net in fast.values():
            net(**x)  # warm-up (kernels, the compiled propagation)
        for _ in range(args.repeats):
            for n, net in fast.items():
                start = time.perf_counter()
                net(**x)
                times[n].append(time.perf_counter() - start)
    ref = times["paper@1/8"]
    print(f"# {cpu_name()}; torch {torch.__version__} f32, BN folded, {size[0]}x{size[1]}, {args.repeats} rounds")
    print(f"{'model':18s} {'GMAC':>7s} {'params':>10s} {'ms':>8s} {'ratio':>7s}")
    result = {}
    for n in names:
        ratio = statistics.median(t / r for t, r in zip(times[n], ref, strict=True))
        ms = 1000 * statistics.median(times[n])
        result[n] = {**info[n], "ms": ms, "ratio_to_paper_w1_8": ratio}
        print(f"{n:18s} {info[n]['gmac']:7.2f} {info[n]['params']:10,d} {ms:8.1f} {ratio:7.3f}")
    if args.json:
        args.json.write_text(json.dumps({"cpu": cpu_name(), "size": size, "results": result}, indent=1))
    return result


if __name__ == "__main__":
    main()
