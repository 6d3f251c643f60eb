"""Accuracy cost of the reduced-precision modes (bf16, int8) on a trained model, next to their speed.

Completes the held-out scenes of a synthetic tree with a trained checkpoint through every
installed inference engine (:func:`semattnet.inference.backends.optimize_for_inference`) in
float32 and in bfloat16 (torch: bf16 autocast with the propagation in float32; OpenVINO: its bf16
inference precision, the propagation in PyTorch float32), and reports for each the four KITTI
metrics, the largest per-pixel difference from eager float32 and the time per frame. On CUDA the
torch fast mode is float16 autocast. bf16 is only worth it on CPUs with native bf16 instructions
(:func:`semattnet._utils.cpu.has_native_bf16`); elsewhere it is reported but emulated and slow.
With ``nncf`` installed, OpenVINO int8 too (NNCF post-training quantisation, calibrated on the
first ``--calibration-frames`` scenes of the tree's *training* split, never on the held-out ones).
``benchmarks/bench_int8_accuracy.py`` is this script.
Typical use, after `semattnet demo`:

    python benchmarks/bench_fast_mode_accuracy.py semattnet-demo/runs/semattnet/full/checkpoints/last.pt \\
        semattnet-demo/data
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from semattnet._utils.cpu import cpu_summary
from semattnet.apps.experiment import HeldOut, load_held_out, score_held_out
from semattnet.data.sources import KittiSplitSource
from semattnet.inference.backends import available_backends, optimize_for_inference
from semattnet.weights import from_pretrained


def _complete(engine, held: HeldOut, device: torch.device) -> tuple[dict[str, np.ndarray], float]:  # type: ignore[no-untyped-def]
    """Refined depth per held-out scene and the median seconds per frame (after one warm-up frame)."""
    preds, times = {}, []
    for i, (n, s) in enumerate(zip(held.names, held.samples, strict=True)):
        x = {k: s[k][None].to(device) for k in ("rgb", "semantic", "sparse")}
        t0 = time.perf_counter()
        out = engine(**x).refined_depth.float()
        if i:
            times.append(time.perf_counter() - t0)
        preds[n] = out[0, 0].cpu().numpy()
    return preds, float(np.median(times)) if times else float("nan")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint", type=Path)
    p.add_argument("data", type=Path, help="a synthetic tree (semattnet synth / demo) with scenes.json")
    p.add_argument("--device", default="cpu")
    p.add_argument("--calibration-frames", type=int, default=32, help="training scenes the int8 engine calibrates on")
    args = p.parse_args()
    device = torch.device(args.device)
    model = from_pretrained(args.checkpoint, progress=False).eval()
    held = load_held_out(args.data)
    size = tuple(held.samples[0]["rgb"].shape[-2:])
    backends = ["torch"] + ([b for b in available_backends() if b == "openvino"] if device.type == "cpu" else [])
    rows = {}
    int8 = importlib.util.find_spec("nncf") is not None
    calibration = KittiSplitSource(args.data, "train", max_frames=args.calibration_frames)
    with tempfile.TemporaryDirectory() as cache:
        for backend in backends:
            for precision in ("f32", "bf16", *(("int8",) if int8 and backend == "openvino" else ())):
                engine = optimize_for_inference(
                    model,
                    backend=backend,
                    size=size,
                    precision=precision,
                    device=device,
                    cache_dir=cache,
                    calibration=calibration,
                    calibration_frames=args.calibration_frames,
                )
                rows[f"{backend} {precision}"] = _complete(engine, held, device)
    ref = rows["torch f32"][0]
    print(f"{cpu_summary()}; {len(held.names)} held-out scenes at {size[0]}x{size[1]}")
    header = ("engine", "RMSE mm", "MAE mm", "iRMSE", "iMAE", "max |d| vs torch f32", "ms/frame")
    print("  ".join(header))
    base = score_held_out(ref, held)["all"]
    for name, (preds, sec) in rows.items():
        m = score_held_out(preds, held)["all"]
        change = max(abs(m[k] / base[k] - 1) for k in ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"))
        diff = max(float(np.abs(preds[n] - ref[n]).max()) for n in held.names)
        print(
            f"{name:14s} {m['rmse_mm']:8.1f} {m['mae_mm']:7.1f} {m['irmse_per_km']:7.2f} {m['imae_per_km']:6.2f} "
            f"{diff:9.4f} m {sec * 1e3:9.1f}   largest metric change {100 * change:.2f} %"
        )


if __name__ == "__main__":
    main()
