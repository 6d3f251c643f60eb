"""Accuracy cost of the fast mode (bf16 / fp16 autocast, propagation in float32) on a trained model.

Completes the held-out scenes of a synthetic tree with a trained checkpoint in float32 and in
the fast mode and reports the refined-depth RMSE of both, their relative difference and the
speed of each at that size. Typical use, after `semattnet demo`:

    python benchmarks/bench_fast_mode_accuracy.py semattnet-demo/runs/semattnet/full/checkpoints/last.pt \\
        semattnet-demo/data
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from semattnet.apps.experiment import load_held_out, score
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.weights.checkpoint import load_model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint", type=Path)
    p.add_argument("data", type=Path, help="a synthetic tree (semattnet synth / demo) with scenes.json")
    p.add_argument("--device", default="cpu")
    args = p.parse_args()
    device = torch.device(args.device)
    dtype = torch.bfloat16 if device.type == "cpu" else torch.float16
    model = fold_batchnorm(load_model(args.checkpoint)).to(device)
    held = load_held_out(args.data)
    results = {}
    for name, amp in (("float32", False), (f"fast ({str(dtype).removeprefix('torch.')})", True)):
        preds, seconds = {}, 0.0
        with torch.inference_mode(), torch.autocast(device.type, dtype=dtype, enabled=amp):
            for n, s in zip(held.names, held.samples, strict=True):
                x = {k: s[k][None].to(device) for k in ("rgb", "semantic", "sparse")}
                t0 = time.perf_counter()
                out = model(**x).refined_depth.float()
                seconds += time.perf_counter() - t0
                preds[n] = out[0, 0].cpu().numpy()
        results[name] = (score(preds, held)["all"]["rmse_mm"], seconds / len(held.names))
    (ref, t_ref), (fast, t_fast) = results.values()
    for name, (rmse, sec) in results.items():
        print(f"{name:16s} RMSE {rmse:9.1f} mm   {sec * 1e3:8.1f} ms/frame")
    print(f"fast mode: RMSE {100 * (fast - ref) / ref:+.3f} % of float32, x{t_ref / t_fast:.2f} speed")


if __name__ == "__main__":
    main()
