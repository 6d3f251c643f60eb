"""Training cost: one step of our trainer against the authors' code and a reconstruction of their recipe,
each in its own process.

Same weights (``authors_code.fill_weights``: equal in every process, by state-dict name), loss (eq. 14 on the
refined depth) and batch (random, ``--size``); variants:

* ``authors-code`` (with ``--authors-src DIR``, a clone of https://github.com/danishnazir/SemAttNet; see
  ``authors_code.py`` for how it is imported and what is shimmed): THEIR ``A_CSPN_plus_plus`` in train mode,
  their forward, our eq. 14 on the depths it returns, stepped as their recipe does
  (:func:`semattnet.training.reference.authors_step`: plain single-tensor Adam, ``zero_grad()`` in place,
  the batch copied to the device);
* ``recipe-reconstruction``: the same step on OUR model with the naive pad-and-sum propagation under
  autograd (:func:`~semattnet.training.reference.authors_step`): a reconstruction of their recipe, not their code;
* ``ours``: :func:`semattnet.training.reference.our_step` (what the trainer runs: fused Adam,
  shifted propagation with its hand-written backward, ``set_to_none``, no batch copies);
* ``ours+ckpt``: the same with activation checkpointing of the branches;
* ``ours+cl`` (``--channels-last``): ours with the model and batch in ``channels_last``.

Every (variant, batch) runs in a fresh process (peak memory is the child's RSS high-water mark,
``VmHWM`` in ``/proc/self/status``, or CUDA's ``max_memory_allocated``), the variants
taken in turns (``--rounds`` times); a child whose RSS passes ``--max-gb`` is stopped and reported
as not fitting. Per-sample memory is the slope of the peak between the smallest and the largest
batch measured (with ``--batches 1,2``: batch 2 - batch 1), or, with batch 1 alone (the default),
the batch-1 peak minus the fixed part (weights, gradients and Adam's two moments, 4 x 4 bytes per
parameter, plus the process before the model), an extrapolation the table says
it is. ``--dry-run`` prints and checks the plan without running it.

    python benchmarks/bench_training.py [--authors-src DIR] [--size 320x1216] [--width 1.0] [--batches 1]
                                        [--rounds 1] [--device cpu] [--max-gb 20] [--profile] [--json out.json]
                                        [--dry-run]

``--profile`` runs one more step per child under ``torch.profiler`` (after the timing and the peak) and reports
the convolutions' self CPU seconds: the same PyTorch calls in every variant, so the reference's step time over
them bounds what any rewrite of the rest can reach.

The speed and memory ratios are to the first variant of each turn: ``authors-code`` when measured, else
``recipe-reconstruction``. ``--width`` other than 1.0 only with the reconstruction (or a test's stand-in):
their released model has one width.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

VARIANTS = ("recipe-reconstruction", "ours", "ours+ckpt")
#: THEIR model's step (``--authors-src``), put first in each turn when measured.
AUTHORS_CODE = "authors-code"
MEMORY_GB = (24, 48, 80)


def plan(variants: tuple[str, ...], batches: tuple[int, ...], rounds: int) -> list[tuple[str, int]]:
    """(variant, batch) in the order they run: per batch, every variant in turn, ``rounds`` times."""
    return [(v, b) for b in batches for _ in range(rounds) for v in variants]


def check_plan(steps: list[tuple[str, int]], variants: tuple[str, ...], batches: tuple[int, ...]) -> None:
    """Every variant at every batch, the first variant (the reference of the ratios) first in each turn."""
    for b in batches:
        ran = [v for v, bb in steps if bb == b]
        assert set(ran) == set(variants) and ran[0] == variants[0], f"batch {b}: {ran}"
        assert all(ran.count(v) == ran.count(variants[0]) for v in variants), f"batch {b}: unequal turns {ran}"


def _model(variant: str, size: tuple[int, int], width: float, authors_src: Path | None) -> Any:
    """The variant's model on the CPU, filled by ``authors_code.fill_weights`` (the same weights in every process)."""
    from authors_code import build_authors_model, fill_weights
    from semattnet.models.registry import build_model

    if variant == AUTHORS_CODE:
        if authors_src is None:
            raise SystemExit(f"{AUTHORS_CODE}: needs --authors-src DIR")
        return build_authors_model(authors_src, size)
    return fill_weights(build_model("semattnet", width=width))


def child(
    variant: str,
    batch: int,
    size: tuple[int, int],
    width: float,
    device: str,
    steps: int,
    warmup: int,
    authors_src: Path | None = None,
    profile: bool = False,
) -> dict[str, Any]:
    """One variant in this process: median seconds per step and peak memory (MiB); with ``profile``, the
    convolutions' share of one more step (:func:`conv_share`, after the peak is read)."""
    import torch

    from semattnet._utils.device import now
    from semattnet.apps.timing import status_mib
    from semattnet.training.checkpointing import set_activation_checkpointing
    from semattnet.training.reference import authors_adam, authors_step, make_adam, our_step

    dev = torch.device(device)
    before = status_mib("VmRSS")
    net = _model(variant, size, width, authors_src).to(dev).train()
    params = sum(p.numel() for p in net.parameters())
    h, w = size
    g = torch.Generator().manual_seed(0)

    def rand(channels: int, scale: float, density: float = 1.0) -> torch.Tensor:
        x = torch.rand(batch, channels, h, w, generator=g) * scale
        return x * (torch.rand(batch, channels, h, w, generator=g) < density) if density < 1 else x

    data = {"rgb": rand(3, 255), "semantic": rand(3, 255), "sparse": rand(1, 80, 0.05), "gt": rand(1, 80, 0.16)}
    if variant == "ours+ckpt":
        set_activation_checkpointing(net)
    if variant == "ours+cl":
        net = net.to(memory_format=torch.channels_last)
        data = {k: v.contiguous(memory_format=torch.channels_last) for k, v in data.items()}
    if variant in (AUTHORS_CODE, "recipe-reconstruction"):  # their step (the latter: naive propagation in ours)
        opt = authors_adam(net.parameters(), lr=1e-4)
        step = lambda: authors_step(net, opt, data, dev)  # noqa: E731
    else:
        data = {k: v.to(dev) for k, v in data.items()}
        opt = make_adam(net.parameters(), dev, lr=1e-4)
        step = lambda: our_step(net, opt, data, dev).item()  # noqa: E731
    if dev.type == "cuda":
        torch.cuda.reset_peak_memory_stats(dev)
    times = []
    for i in range(warmup + steps):
        t0 = now(dev)
        step()
        if i >= warmup:
            times.append(now(dev) - t0)
    peak = torch.cuda.max_memory_allocated(dev) / 2**20 if dev.type == "cuda" else _peak_rss_mib()
    out = {
        "variant": variant,
        "batch": batch,
        "seconds": statistics.median(times),
        "peak_mib": peak,
        "before_mib": before if dev.type == "cpu" else 0.0,
        "params": params,
    }
    return {**out, **conv_share(step)} if profile and dev.type == "cpu" else out


def _peak_rss_mib() -> float:
    """This process's resident high-water mark (``VmHWM``: since its ``exec``, unlike ``ru_maxrss``, which Linux
    carries over from the parent)."""
    from semattnet.apps.timing import status_mib

    peak = status_mib("VmHWM")
    return peak if not math.isnan(peak) else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB, no /proc


def conv_share(step: Any) -> dict[str, float]:
    """One more ``step()`` under ``torch.profiler``: the self CPU seconds of the convolution operators (forward
    and backward, every ``aten::*convolution*``) and of all operators. The convolutions are the same library
    calls in every variant, so ``reference seconds / conv seconds`` bounds the speed-up of a variant that
    keeps them."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        step()
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events) / 1e6
    conv = sum(e.self_cpu_time_total for e in events if "convolution" in e.key) / 1e6
    return {"conv_seconds": conv, "profiled_seconds": total}


def _run_child(args: argparse.Namespace, variant: str, batch: int) -> dict[str, Any] | None:
    """The child process of one (variant, batch); None if it passed ``--max-gb`` (stopped) or failed."""
    cmd = [
        sys.executable,
        __file__,
        "--child",
        variant,
        "--batches",
        str(batch),
        "--size",
        args.size,
        "--width",
        str(args.width),
        "--device",
        args.device,
        "--steps",
        str(args.steps),
        "--warmup",
        str(args.warmup),
    ]
    cmd += ["--authors-src", str(args.authors_src)] if args.authors_src else []
    cmd += ["--profile"] if args.profile else []
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    status = Path(f"/proc/{proc.pid}/status")  # read here, not through semattnet: the parent imports no torch
    while proc.poll() is None:
        try:
            rss = next(int(ln.split()[1]) for ln in status.read_text().splitlines() if ln.startswith("VmRSS:"))
        except (OSError, StopIteration):
            rss = 0
        if rss > args.max_gb * 2**20:
            proc.kill()
            proc.wait()
            print(f"  {variant} batch {batch}: stopped above {args.max_gb} GB RSS (does not fit)", flush=True)
            return None
        time.sleep(0.2)
    out = proc.stdout.read() if proc.stdout else ""
    if proc.returncode != 0:
        print(f"  {variant} batch {batch}: failed (exit {proc.returncode})", flush=True)
        return None
    return json.loads(out.strip().splitlines()[-1])


def summarise(results: list[dict[str, Any]], variants: tuple[str, ...]) -> list[str]:
    """The table: medians per (variant, batch), ratios to the reference (the first variant: ``authors-code`` or
    ``recipe-reconstruction``), per-sample memory, batches that fit."""
    ref_name = variants[0]
    head = f"{'batch':>5s} {'s/step':>8s} {'x speed':>9s} {'peak GiB':>9s} {'x memory':>11s}"
    lines = [f"ratios to {ref_name}", f"{'variant':21s} {head}"]
    med: dict[tuple[str, int], tuple[float, float]] = {}
    for v in variants:
        for b in sorted({r["batch"] for r in results}):
            rs = [r for r in results if r["variant"] == v and r["batch"] == b]
            if rs:
                med[v, b] = (statistics.median(r["seconds"] for r in rs), statistics.median(r["peak_mib"] for r in rs))
    for (v, b), (sec, peak) in med.items():
        ref = med.get((ref_name, b))
        speed = f"{ref[0] / sec:9.2f}" if ref else " " * 9
        mem = f"{peak / ref[1]:11.2f}" if ref else " " * 11
        lines.append(f"{v:21s} {b:5d} {sec:8.2f} {speed} {peak / 1024:9.2f} {mem}")
    lines += _against_ours(med) + _conv_bound(results, variants)
    lines += ["", f"{'variant':21s} {'GiB/sample':>10s} {'fixed GiB':>9s} " + " ".join(f"{g:>4d}GB" for g in MEMORY_GB)]
    for v in variants:
        fit = _per_sample(results, med, v)
        if fit is not None:
            per, fixed, how = fit
            fits = " ".join(f"{max(0, int((g * 1e9 / 2**20 - fixed) // per)):6d}" for g in MEMORY_GB)
            lines.append(f"{v:21s} {per / 1024:10.2f} {fixed / 1024:9.2f} {fits}   ({how})")
    return lines


def _against_ours(med: dict[tuple[str, int], tuple[float, float]]) -> list[str]:
    """Activation checkpointing against ours without, per batch: step time and peak memory ratios."""
    rows = [
        f"{'ours+ckpt / ours':16s} batch {b}: step time {med['ours+ckpt', b][0] / med['ours', b][0]:.2f}x, "
        f"peak memory {med['ours+ckpt', b][1] / med['ours', b][1]:.2f}x"
        for b in sorted({b for _, b in med})
        if ("ours", b) in med and ("ours+ckpt", b) in med
    ]
    return ["", *rows] if rows else []


def _conv_bound(results: list[dict[str, Any]], variants: tuple[str, ...]) -> list[str]:
    """With ``--profile``: each variant's convolution seconds (the same library calls in every variant) and the
    speed-up over the reference that a step made of nothing else would reach."""
    prof = [r for r in results if "conv_seconds" in r]
    if not prof:
        return []
    lines = ["", f"{'variant':21s} {'batch':>5s} {'conv s':>8s} {'other s':>8s} {'conv %':>7s} {'bound':>7s}"]
    for r in prof:
        ref = next((q for q in prof if q["variant"] == variants[0] and q["batch"] == r["batch"]), None)
        bound = f"{ref['seconds'] / r['conv_seconds']:6.2f}x" if ref else ""
        share = 100 * r["conv_seconds"] / r["profiled_seconds"]
        other = r["profiled_seconds"] - r["conv_seconds"]
        lines.append(
            f"{r['variant']:21s} {r['batch']:5d} {r['conv_seconds']:8.2f} {other:8.2f} {share:6.1f}% {bound:>7s}"
        )
    return [*lines, "(one more step under torch.profiler, self CPU seconds; bound: reference s/step / conv s)"]


def _per_sample(
    results: list[dict[str, Any]], med: dict[tuple[str, int], tuple[float, float]], v: str
) -> tuple[float, float, str] | None:
    """(MiB per sample, fixed MiB, how it was obtained) of variant ``v``: from its smallest and largest
    measured batches, else extrapolated from batch 1."""
    batches = sorted(b for vv, b in med if vv == v)
    if len(batches) >= 2:
        lo, hi = batches[0], batches[-1]
        per = (med[v, hi][1] - med[v, lo][1]) / (hi - lo)
        return per, med[v, lo][1] - lo * per, f"measured: (batch {hi} - batch {lo}) / {hi - lo}"
    one = [r for r in results if r["variant"] == v and r["batch"] == 1]
    if not one:
        return None
    fixed = one[0]["before_mib"] + 16 * one[0]["params"] / 2**20  # weights, grads, two Adam moments
    return med[v, 1][1] - fixed, fixed, "extrapolated from batch 1: peak - weights/grads/Adam"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="320x1216")
    p.add_argument("--width", type=float, default=1.0)
    what = f"a clone of danishnazir/SemAttNet: adds the {AUTHORS_CODE} variant, first in each turn"
    p.add_argument("--authors-src", type=Path, default=None, help=what)
    p.add_argument("--batches", default="1")
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--steps", type=int, default=1, help="timed steps per process (median)")
    p.add_argument("--warmup", type=int, default=1, help="untimed steps before (allocates Adam's state)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--max-gb", type=float, default=20.0, help="stop a child whose RSS passes this")
    p.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated, in the order of each turn")
    p.add_argument("--channels-last", action="store_true", help="also measure ours in channels_last")
    p.add_argument(
        "--profile",
        action="store_true",
        help="also time the convolutions of one more step (torch.profiler): their share and the bound",
    )
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--dry-run", action="store_true")
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    batches = tuple(int(b) for b in args.batches.split(","))
    if args.child:
        print(
            json.dumps(
                child(
                    args.child,
                    batches[0],
                    size,
                    args.width,
                    args.device,
                    args.steps,
                    args.warmup,  # type: ignore[arg-type]
                    args.authors_src,
                    args.profile,
                )
            )
        )
        return 0
    variants = tuple(args.variants.split(",")) + (("ours+cl",) if args.channels_last else ())
    if args.authors_src is not None and AUTHORS_CODE not in variants:
        variants = (AUTHORS_CODE, *variants)
    if AUTHORS_CODE in variants and args.authors_src is None:
        p.error(f"--variants {AUTHORS_CODE} needs --authors-src DIR")
    if not set(variants) <= {*VARIANTS, AUTHORS_CODE, "ours+cl"}:
        p.error(f"--variants: expected some of {', '.join(VARIANTS)}, got {args.variants!r}")
    steps = plan(variants, batches, args.rounds)
    check_plan(steps, variants, batches)
    print(
        f"plan: {len(steps)} processes at {size[0]}x{size[1]}, width {args.width}, {args.device}: "
        + ", ".join(f"{v}@{b}" for v, b in steps),
        flush=True,
    )
    if args.dry_run:
        return 0
    print(f"load before: {os.getloadavg()}", flush=True)
    results = []
    for v, b in steps:
        r = _run_child(args, v, b)
        if r is not None:
            print(f"  {v} batch {b}: {r['seconds']:.2f} s/step, peak {r['peak_mib'] / 1024:.2f} GiB", flush=True)
            results.append(r)
    print("\n".join(summarise(results, variants)))
    if args.json:
        args.json.write_text(json.dumps({"args": vars(args), "results": results}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
