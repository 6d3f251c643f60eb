"""Where the float32 OpenVINO graph spends its time: per-layer times beside each layer's MACs.

    python benchmarks/bench_layers.py [--size 352x1216] [--width 1.0] [--runs 5] [--top 30] [--json out.json]

Builds ours (random weights) through ``optimize_for_inference(backend="openvino", size=SIZE)`` in a temporary
cache, compiles the cached IR again with OpenVINO's performance counters (``PERF_COUNT``; the same hints as the
engine: LATENCY, f32, this process's threads) and runs it ``--runs`` times on a random frame. Per layer: the
median of its times over the runs, its MACs (convolutions: output elements x kernel taps x input channels;
transposed: input elements x output channels x taps), its rate, and what it **loses** against the best rate
any large convolution of the same graph reaches on this CPU (``attainable``: the highest rate among layers
of at least 1 GMAC): ``time - MACs / attainable``. The table lists the layers that lose most, and the total:
the graph's time against ``MACs / attainable``, the floor of this engine on this CPU.
"""

from __future__ import annotations

import argparse
import collections
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

#: Layers of at least this many MACs set the attainable rate (small ones are dominated by memory traffic).
BIG_LAYER_MACS = 1e9


def layer_macs(model: Any) -> dict[str, int]:
    """Friendly name -> multiply-accumulates of every (transposed) convolution of an ``ov.Model``."""
    macs = {}
    for op in model.get_ordered_ops():
        kind = op.get_type_name()
        if kind not in ("Convolution", "GroupConvolution", "ConvolutionBackpropData"):
            continue
        out = list(op.get_output_partial_shape(0).to_shape())
        w = list(op.input(1).get_source_output().get_partial_shape().to_shape())
        if kind == "Convolution":  # w: (out, in, kh, kw)
            n = np.prod(out) * np.prod(w[1:])
        elif kind == "GroupConvolution":  # w: (groups, out/g, in/g, kh, kw)
            n = np.prod(out) * np.prod(w[2:])
        else:  # transposed, w: (in, out, kh, kw): every input element meets every tap of every output channel
            n = np.prod(list(op.input(0).get_source_output().get_partial_shape().to_shape())) * np.prod(w[1:])
        macs[op.get_friendly_name()] = int(n)
    return macs


def fused_names(model: Any) -> dict[str, str]:
    """Other names a convolution's layer may have in the profile -> its name: OpenVINO fuses the bias ``Add``
    into it, and a layer that ends at a graph output takes that output's name."""
    names = {}
    for op in model.get_ordered_ops():
        if op.get_type_name() not in ("Convolution", "GroupConvolution", "ConvolutionBackpropData"):
            continue
        for after in (t.get_node() for t in op.output(0).get_target_inputs()):
            if after.get_type_name() == "Add":
                for name in (after.get_friendly_name(), *after.output(0).get_names()):
                    names[name] = op.get_friendly_name()
    return names


def profile_graph(xml: Path, runs: int) -> tuple[list[float], dict[tuple[str, str, str], float], dict[str, int]]:
    """(wall seconds of each run, (name, type, kernel) -> median seconds, name -> MACs) of the IR ``xml``."""
    import openvino as ov

    core = ov.Core()
    model = core.read_model(str(xml))
    macs, aliases = layer_macs(model), fused_names(model)
    config = {
        "PERFORMANCE_HINT": "LATENCY",
        "INFERENCE_PRECISION_HINT": "f32",
        "INFERENCE_NUM_THREADS": torch.get_num_threads(),
        "PERF_COUNT": True,
    }
    compiled = core.compile_model(model, "CPU", config)
    request = compiled.create_infer_request()
    rng = np.random.default_rng(0)
    feeds = [rng.random(tuple(i.get_shape()), dtype=np.float32) * 80 for i in compiled.inputs]
    request.infer(feeds)  # the warm-up
    walls, times = [], collections.defaultdict(list)
    for _ in range(runs):
        t0 = time.perf_counter()
        request.infer(feeds)
        walls.append(time.perf_counter() - t0)
        for p in request.get_profiling_info():
            name = p.node_name if p.node_name in macs else aliases.get(p.node_name, p.node_name)
            times[name, p.node_type, p.exec_type].append(p.real_time.total_seconds())
    return walls, {k: statistics.median(v) for k, v in times.items() if max(v) > 0}, macs


def analyse(times: dict[tuple[str, str, str], float], macs: dict[str, int]) -> dict[str, Any]:
    """The attainable rate, the floor, and every layer's loss against it (largest first)."""
    rates = [macs[n] / s for (n, _, _), s in times.items() if macs.get(n, 0) >= BIG_LAYER_MACS and s > 0]
    attainable = max(rates) if rates else float("nan")
    layers = [
        {
            "name": n,
            "type": t,
            "kernel": e,
            "ms": 1e3 * s,
            "gmac": macs.get(n, 0) / 1e9,
            "lost_ms": 1e3 * (s - macs.get(n, 0) / attainable),
        }
        for (n, t, e), s in times.items()
    ]
    layers.sort(key=lambda r: -r["lost_ms"])
    total_s, total_mac = sum(times.values()), sum(macs.values())
    return {
        "attainable_gmac_s": attainable / 1e9,
        "layers_s": total_s,
        "gmac": total_mac / 1e9,
        "floor_s": total_mac / attainable,
        "layers": layers,
    }


def table(r: dict[str, Any], top: int) -> list[str]:
    lines = [
        f"CPU: {r['cpu']}; {r['size'][0]}x{r['size'][1]}, float32, {r['threads']} threads, median of {r['runs']}",
        f"graph: {r['wall_s']:.3f} s a run (layers {r['layers_s']:.3f} s); {r['gmac']:.1f} GMAC; attainable "
        f"{r['attainable_gmac_s']:.1f} GMAC/s (the best large layer); floor {r['floor_s']:.3f} s "
        f"({100 * r['floor_s'] / r['layers_s']:.0f} % of the layers' time)",
        f"{'lost ms':>8s} {'ms':>8s} {'GMAC':>7s} {'GMAC/s':>7s}  {'type':24s} layer",
    ]
    for x in r["layers"][:top]:
        rate = f"{x['gmac'] / x['ms'] * 1e3:7.1f}" if x["gmac"] else " " * 7
        lines.append(f"{x['lost_ms']:8.1f} {x['ms']:8.1f} {x['gmac']:7.2f} {rate}  {x['type']:24s} {x['name'][:70]}")
    by_type = collections.Counter()
    for x in r["layers"]:
        by_type[x["type"]] += x["lost_ms"]
    lines.append("lost by type: " + ", ".join(f"{t} {ms:.0f} ms" for t, ms in by_type.most_common(6)))
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="352x1216")
    p.add_argument("--width", type=float, default=1.0)
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--top", type=int, default=30)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    import semattnet
    from semattnet._utils.cpu import cpu_summary
    from semattnet.inference.backends import optimize_for_inference

    size = tuple(int(v) for v in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory() as cache:
        net = semattnet.build_model("semattnet", width=args.width).eval()
        optimize_for_inference(net, backend="openvino", size=size, cache_dir=cache)
        walls, times, macs = profile_graph(next(Path(cache).glob("engines/*/model.xml")), args.runs)
    r = {
        "cpu": cpu_summary(),
        "size": list(size),
        "threads": torch.get_num_threads(),
        "runs": args.runs,
        "wall_s": statistics.median(walls),
        **analyse(times, macs),
    }
    print("\n".join(table(r, args.top)))
    if args.json:
        args.json.write_text(json.dumps(r, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
