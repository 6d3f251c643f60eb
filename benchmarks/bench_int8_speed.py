"""int8 speed: the naive reference against OpenVINO float32 and int8, timed in turns in one process.

The full model at ``--size`` (default 352x1216, width 1.0, random weights from seed 0, batch 1):
the naive reference is the model with the authors' pad-and-sum propagation
(``propagation_impl="naive"``, BatchNorm layers kept), the engines are
``optimize_for_inference(backend="openvino", precision=...)`` (int8: NNCF post-training
quantisation calibrated on the default synthetic scenes; built once, then cached under
``$SEMATTNET_CACHE``). Each engine runs once before the timed turns; the median of ``--repeats``
turns is reported with the ratio to the naive reference and the largest relative difference.

    python benchmarks/bench_int8_speed.py [--size 352x1216] [--width 1.0] [--repeats 3]
                                          [--precisions f32,int8] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

import torch

import semattnet
from semattnet.apps.benchmark import random_frame
from semattnet.apps.timing import interleaved
from semattnet.inference.backends import optimize_for_inference


def measure(size: tuple[int, int], width: float, precisions: tuple[str, ...], repeats: int) -> dict[str, Any]:
    """Median seconds per frame of the naive reference and each OpenVINO precision, and their differences."""
    torch.manual_seed(0)
    net = semattnet.build_model("semattnet", width=width).eval()
    x = random_frame(size, torch.device("cpu"))

    def naive() -> Any:
        net.propagation_impl = "naive"
        try:
            return net(**x)
        finally:
            net.propagation_impl = "auto"

    runs = {"naive reference": naive}
    for p in precisions:
        engine = optimize_for_inference(net, backend="openvino", size=size, precision=p, log=print)
        runs[f"openvino {p}"] = lambda e=engine: e(**x)
    with torch.inference_mode():
        outs = {k: f().refined_depth for k, f in runs.items()}  # also the warm-up
        seconds = interleaved(runs, torch.device("cpu"), repeats)
    ref = outs["naive reference"]
    diff = {k: float((o - ref).abs().max() / ref.abs().max()) for k, o in outs.items()}
    return {"seconds": seconds, "max_rel_diff": diff, "load_after": os.getloadavg()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="352x1216")
    p.add_argument("--width", type=float, default=1.0)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--precisions", default="f32,int8")
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    h, w = (int(v) for v in args.size.lower().split("x"))
    print(f"load before: {os.getloadavg()}", flush=True)
    r = measure((h, w), args.width, tuple(args.precisions.split(",")), args.repeats)
    base = r["seconds"]["naive reference"]
    for k, sec in r["seconds"].items():
        print(f"{k:18s} {sec:7.2f} s   x naive {base / sec:5.2f}   max rel diff {r['max_rel_diff'][k]:.1e}")
    print(f"load after: {r['load_after']}")
    if args.json:
        args.json.write_text(json.dumps(r, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
