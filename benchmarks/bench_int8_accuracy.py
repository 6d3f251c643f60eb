"""int8 against float32 (OpenVINO) on the shipped trained weights: the four KITTI metrics, the largest pixel
change and the speed-up, with the calibration a user gets.

For each of ``--weights`` (registry names or checkpoint files; default the two shipped reference checkpoints,
``semattnet-demo-ref-seed0`` and ``-seed1``) the script completes the demo's 16 held-out scenes (96x320,
"realistic" style, data seed 0: written here by the demo's own generator, as ``semattnet.apps.front_figure``
does, so no demo run is needed; the reference checkpoints were trained on data seed 1000) with OpenVINO float32
and OpenVINO int8 (``optimize_for_inference(..., precision="int8")``: NNCF calibrated on what
``--calibration`` names, by default what a user gets, the default synthetic scenes; never on the held-out
scenes), and prints per checkpoint the metrics as the demo scores them
(:func:`semattnet.apps.experiment.score_held_out`, "all"), their relative change, the largest per-pixel change and the
median time per frame of each engine, the two timed in turns in this process, with the CPU named.

    python benchmarks/bench_int8_accuracy.py [--weights semattnet-demo-ref-seed0,semattnet-demo-ref-seed1]
        [--calibration PATH] [--calibration-frames 8] [--json out.json]

``--dry-run`` writes the scenes and loads the weights but builds no engine (a check that the script runs).
The older form ``bench_int8_accuracy.py CHECKPOINT SYNTH_TREE`` (every engine, bf16 too, calibrated on the
tree's training split) is ``bench_fast_mode_accuracy.py``, which it still runs.
"""

from __future__ import annotations

import argparse
import json
import logging
import runpy
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

KEYS = ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km")
DEFAULT_WEIGHTS = "semattnet-demo-ref-seed0,semattnet-demo-ref-seed1"


def _args(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--weights", default=DEFAULT_WEIGHTS, help="comma-separated registry names or checkpoint files")
    p.add_argument("--calibration", default=None, help="int8 calibration folder (default: the synthetic scenes)")
    p.add_argument("--calibration-frames", type=int, default=None, help="calibration frames (default: the library's)")
    p.add_argument("--scenes", type=int, default=16, help="held-out scenes completed (the demo's: 16)")
    p.add_argument("--repeats", type=int, default=3, help="timed passes over the scenes, f32 and int8 in turns")
    p.add_argument(
        "--speed-size",
        default=None,
        metavar="HxW",
        help="also time both engines on a random frame of this size (e.g. 352x1216; minutes)",
    )
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    p.add_argument("--dry-run", action="store_true", help="scenes and weights only, no engine")
    return p.parse_args(argv)


def held_out_scenes(work: Path, scenes: int) -> Any:
    """The demo's held-out scenes (:class:`~semattnet.apps.experiment.HeldOut`), the first ``scenes`` of them."""
    from semattnet.apps.demo.recipe import DemoSettings
    from semattnet.apps.experiment import make_synthetic

    s = DemoSettings()
    # the held-out scenes depend only on the seed, the size and the style: one training frame is written, unused
    held = make_synthetic(work / "data", 1, s.eval_frames, s.size, s.seed, style=s.style)
    held.names, held.samples = held.names[:scenes], held.samples[:scenes]
    return held


def _load(weights: str) -> Any:
    from semattnet.weights import from_pretrained

    return from_pretrained(weights).eval()


def _timed(engine: Any, sample: dict[str, Any]) -> tuple[np.ndarray, float]:
    x = {k: sample[k][None] for k in ("rgb", "semantic", "sparse")}
    t0 = time.perf_counter()
    depth = engine(**x).refined_depth.float()[0, 0].numpy()
    return depth, time.perf_counter() - t0


def compare(model: Any, held: Any, args: argparse.Namespace, cache: Path) -> dict[str, Any]:
    """float32 and int8 OpenVINO engines of ``model`` on ``held``: metrics, changes, times."""
    from semattnet.apps.experiment import score_held_out
    from semattnet.inference.backends import optimize_for_inference
    from semattnet.inference.backends.calibration import DEFAULT_CALIBRATION_FRAMES

    size = tuple(held.samples[0]["rgb"].shape[-2:])
    frames = args.calibration_frames or DEFAULT_CALIBRATION_FRAMES
    engines = {
        p: optimize_for_inference(
            model,
            backend="openvino",
            size=size,
            precision=p,
            cache_dir=cache,
            calibration=args.calibration,
            calibration_frames=frames,
        )
        for p in ("f32", "int8")
    }
    preds: dict[str, dict[str, np.ndarray]] = {p: {} for p in engines}
    times: dict[str, list[float]] = {p: [] for p in engines}
    for r in range(args.repeats + 1):  # pass 0: warm-up, its outputs scored
        for name, sample in zip(held.names, held.samples, strict=True):
            for p in engines if r % 2 else reversed(engines):  # in turns, the order swapped each pass
                depth, sec = _timed(engines[p], sample)
                preds[p].setdefault(name, depth)
                if r:
                    times[p].append(sec)
    m = {p: score_held_out(preds[p], held)["all"] for p in engines}
    ms = {p: 1e3 * statistics.median(times[p]) if times[p] else float("nan") for p in engines}
    return {
        "f32": {k: m["f32"][k] for k in KEYS},
        "int8": {k: m["int8"][k] for k in KEYS},
        "change_pct": {k: 100 * (m["int8"][k] / m["f32"][k] - 1) for k in KEYS},
        "max_pixel_change_m": max(float(np.abs(preds["int8"][n] - preds["f32"][n]).max()) for n in held.names),
        "ms_per_frame": ms,
        "speedup": ms["f32"] / ms["int8"],
    }


def speed_at(model: Any, size: tuple[int, int], args: argparse.Namespace, cache: Path) -> dict[str, float]:
    """Median ms per frame of the float32 and int8 engines at ``size`` (a random frame, timed in turns) and the
    speed-up."""
    import torch

    from semattnet.apps.benchmark import random_frame
    from semattnet.apps.timing import interleaved
    from semattnet.inference.backends import optimize_for_inference
    from semattnet.inference.backends.calibration import DEFAULT_CALIBRATION_FRAMES

    x = random_frame(size, torch.device("cpu"))
    frames = args.calibration_frames or DEFAULT_CALIBRATION_FRAMES
    runs = {}
    for p in ("f32", "int8"):
        engine = optimize_for_inference(
            model,
            backend="openvino",
            size=size,
            precision=p,
            cache_dir=cache,
            calibration=args.calibration,
            calibration_frames=frames,
        )
        engine(**x)  # warm-up
        runs[p] = lambda e=engine: e(**x)
    seconds = interleaved(runs, torch.device("cpu"), args.repeats)
    ms = {p: 1e3 * sec for p, sec in seconds.items()}
    return {"f32_ms": ms["f32"], "int8_ms": ms["int8"], "speedup": ms["f32"] / ms["int8"]}


def report(results: dict[str, Any]) -> None:
    """The table of :func:`compare`'s numbers per checkpoint."""
    print(
        f"{results['cpu']}; {results['scenes']} held-out scenes at {results['size'][0]}x{results['size'][1]}; "
        f"int8 calibrated on {results['calibration']}"
    )
    print("weights                       engine  RMSE mm  MAE mm  iRMSE  iMAE   ms/frame")
    for name, r in results["weights"].items():
        for p in ("f32", "int8"):
            m = r[p]
            print(
                f"{name:29s} {p:6s} {m['rmse_mm']:8.1f} {m['mae_mm']:7.1f} {m['irmse_per_km']:6.3f} "
                f"{m['imae_per_km']:5.3f} {r['ms_per_frame'][p]:9.1f}"
            )
        c = r["change_pct"]
        print(
            f"{'':29s} change {c['rmse_mm']:+7.2f}% {c['mae_mm']:+6.2f}% {c['irmse_per_km']:+5.2f}% "
            f"{c['imae_per_km']:+5.2f}%   largest pixel change {r['max_pixel_change_m']:.2f} m, "
            f"int8 {r['speedup']:.2f}x f32 (timings indicative)"
        )
        if "speed_at" in r:
            t = r["speed_at"]
            print(
                f"{'':29s} at {results['speed_size'][0]}x{results['speed_size'][1]}: f32 {t['f32_ms']:.0f} ms, "
                f"int8 {t['int8_ms']:.0f} ms, int8 {t['speedup']:.2f}x f32"
            )


def main(argv: list[str]) -> dict[str, Any] | None:
    """Run the benchmark of the module docstring; the numbers (None for ``--dry-run``)."""
    from semattnet._utils.cpu import cpu_summary
    from semattnet.inference.backends.calibration import DEFAULT_CALIBRATION_FRAMES, resolve_calibration

    args = _args(argv)
    logging.getLogger("nncf").setLevel(logging.WARNING)  # its per-layer notes
    with tempfile.TemporaryDirectory() as work:
        held = held_out_scenes(Path(work), args.scenes)
        models = {w: _load(w) for w in args.weights.split(",")}
        size = tuple(held.samples[0]["rgb"].shape[-2:])
        frames = args.calibration_frames or DEFAULT_CALIBRATION_FRAMES
        calibration = resolve_calibration(args.calibration, size, frames).description  # type: ignore[arg-type]
        if args.dry_run:
            print(f"dry run: {len(held.names)} scenes at {size}, weights {', '.join(models)}, int8 on {calibration}")
            return None
        results: dict[str, Any] = {
            "cpu": cpu_summary(),
            "scenes": len(held.names),
            "size": list(size),
            "calibration": calibration,
            "weights": {},
        }
        speed = tuple(int(v) for v in args.speed_size.split("x")) if args.speed_size else None
        for name, model in models.items():
            results["weights"][name] = compare(model, held, args, Path(work) / "cache")
            if speed is not None:
                results["speed_size"] = list(speed)
                results["weights"][name]["speed_at"] = speed_at(model, speed, args, Path(work) / "cache")  # type: ignore[arg-type]
    report(results)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    if len(sys.argv) > 2 and not sys.argv[1].startswith("-"):  # the older CHECKPOINT SYNTH_TREE form
        runpy.run_path(str(Path(__file__).with_name("bench_fast_mode_accuracy.py")), run_name="__main__")
    else:
        main(sys.argv[1:])
