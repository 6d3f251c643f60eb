"""The CUDA path, measured by one prepared script (under 8 minutes on one GPU).

    python benchmarks/gpu.py [--json gpu.json] [--budget 450]    # on a machine with a GPU
    python benchmarks/gpu.py --dry-run                           # prints and checks the plan (CPU)

Steps (each skipped with a note when its package is missing, or when the time budget is spent):

1. **parity** of every CUDA backend against the eager float32 model (BN layers, the eager
   propagation) on one 352x1216 frame: ``eager`` (BN folded), ``fp16`` / ``bf16`` autocast
   (propagation in float32), ``compile`` (network and propagation through ``torch.compile``),
   ``cudagraphs`` (``torch.compile(mode="reduce-overhead")``: CUDA graphs at a fixed size),
   ``tensorrt`` (``optimize_for_inference(backend="tensorrt")``, when ``torch_tensorrt`` imports);
2. **latency** of each at 352x1216, batch 1 and 8: median and p95 of ``--repeats`` runs, and the
   allocator's peak memory;
3. **propagation**: the CSPN++ stages eager (shifted form) against ``torch.compile``
   (:mod:`semattnet.inference.backends.compiled_propagation`) and the authors' pad-and-sum;
4. **training**: step time, samples/s and peak memory at 320x1216, batch ``--train-batch``,
   with and without activation checkpointing (``semattnet.training.checkpointing``).

The parity and latency functions are device-agnostic: ``tests/benchmarks/test_gpu_script.py``
runs them on the CPU at a tiny size (the backends that need no compilation) and checks the plan.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

#: (name, what it builds, float tolerance: max |d| / max |ref| of refined_depth against eager float32)
BACKENDS: tuple[tuple[str, str, float], ...] = (
    ("eager", "TorchEngine f32, BN folded, eager propagation", 1e-4),
    ("torch", "TorchEngine as on CUDA by default: eager network, compiled propagation", 1e-4),
    ("fp16", "TorchEngine fp16 autocast, propagation float32", 5e-2),
    ("bf16", "TorchEngine bf16 autocast, propagation float32", 1e-1),
    ("compile", "torch.compile of the network + compiled propagation", 1e-4),
    ("cudagraphs", "torch.compile(mode='reduce-overhead'): CUDA graphs at a fixed size", 1e-4),
    ("tensorrt", "optimize_for_inference(backend='tensorrt'), f32", 1e-3),
)
#: Seconds each step may take at most on one recent GPU (the plan's own budget check).
STEP_BUDGET = {"parity": 200, "latency": 120, "propagation": 40, "training": 90}
SIZE, TRAIN_SIZE = (352, 1216), (320, 1216)


def frame(batch: int, size: tuple[int, int], device: torch.device, seed: int = 0) -> dict[str, torch.Tensor]:
    """Random inputs in the model's units (colours 0..255, 5 % sparse depth in metres)."""
    h, w = size
    g = torch.Generator().manual_seed(seed)
    rgb, semantic = (torch.rand(batch, 3, h, w, generator=g) * 255 for _ in range(2))
    sparse = torch.rand(batch, 1, h, w, generator=g) * 80 * (torch.rand(batch, 1, h, w, generator=g) < 0.05)
    x = {"rgb": rgb, "semantic": semantic, "sparse": sparse}
    return {k: v.to(device) for k, v in x.items()}


def available(name: str, device: torch.device) -> str | None:
    """None if backend ``name`` can run here, else why not."""
    compiled = name in ("torch", "compile", "cudagraphs")
    if compiled and device.type != "cuda":
        return "torch.compile takes minutes on this CPU: its code path is checked traced instead"
    if name == "tensorrt" and importlib.util.find_spec("torch_tensorrt") is None:
        return "torch_tensorrt is not installed (pip install 'semattnet[tensorrt]')"
    if name in ("tensorrt", "cudagraphs", "fp16") and device.type != "cuda":
        return f"{name} needs CUDA"
    if compiled and device.type == "cuda" and importlib.util.find_spec("triton") is None:
        return "triton is not installed"
    return None


def build(name: str, model: torch.nn.Module, device: torch.device, size: tuple[int, int]) -> Callable[..., Any]:
    """``fn(**inputs) -> DepthCompletionOutput`` of backend ``name`` (see :data:`BACKENDS`)."""
    from semattnet.inference.backends import optimize_for_inference
    from semattnet.inference.backends.compiled_propagation import compiled_propagation
    from semattnet.models.outputs import DepthCompletionOutput

    if name in ("tensorrt", "torch"):
        return optimize_for_inference(model, backend=name, size=size, device=device)
    precision = name if name in ("fp16", "bf16") else "f32"
    engine = optimize_for_inference(
        model, backend="torch", precision=precision, device=device, compile_propagation=False
    )
    if name not in ("compile", "cudagraphs"):
        return engine
    mode = "reduce-overhead" if name == "cudagraphs" else None
    network = torch.compile(engine.net.forward_network, dynamic=False, mode=mode)
    propagate = compiled_propagation(mode)

    def run(**x: torch.Tensor) -> DepthCompletionOutput:
        with torch.inference_mode():
            out, heads = network(**x)
            s2, refined = propagate(heads, engine.net.config.iterations)
            refinement = {"refined_s2_depth": s2.clone(), "refined_depth": refined.clone()}  # out of the graph pool
            return DepthCompletionOutput(**(out.to_dict() | refinement))

    return run


def parity(fn: Callable[..., Any], reference: torch.Tensor, x: dict[str, torch.Tensor]) -> float:
    """max |d| / max |ref| of ``fn``'s refined depth against ``reference``."""
    out = fn(**x).refined_depth.float()
    return float((out - reference.float()).abs().max() / reference.float().abs().max())


def latency(fn: Callable[[], Any], device: torch.device, repeats: int) -> dict[str, float]:
    """Median and p95 seconds of ``fn()`` (after two warm-up runs) and the allocator's peak MiB."""
    from semattnet._utils.device import now

    for _ in range(2):
        fn()
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    times = []
    for _ in range(repeats):
        t0 = now(device)
        fn()
        times.append(now(device) - t0)
    times.sort()
    peak = torch.cuda.max_memory_allocated(device) / 2**20 if device.type == "cuda" else float("nan")
    return {
        "median_s": statistics.median(times),
        "p95_s": times[min(len(times) - 1, int(0.95 * len(times)))],
        "peak_mib": peak,
    }


def plan(device: torch.device, train_batch: int) -> list[dict[str, Any]]:
    """The steps in order, each with what it runs and whether it can run here."""
    steps = [
        {"step": "parity", "backend": n, "what": what, "tol": tol, "skip": available(n, device)}
        for n, what, tol in BACKENDS
    ]
    steps += [
        {"step": "latency", "backend": n, "batch": b, "skip": available(n, device)}
        for b in (1, 8)
        for n, _, _ in BACKENDS
    ]
    steps.append({"step": "propagation", "skip": None})
    steps += [{"step": "training", "checkpointing": c, "batch": train_batch, "skip": None} for c in (False, True)]
    return steps


def check_plan(steps: list[dict[str, Any]], budget: float) -> None:
    """Every backend has a parity check before its latency; both batches; both training modes; in budget."""
    names = [n for n, _, _ in BACKENDS]
    assert [s["backend"] for s in steps if s["step"] == "parity"] == names
    for b in (1, 8):
        assert [s["backend"] for s in steps if s["step"] == "latency" and s["batch"] == b] == names
    assert {s["checkpointing"] for s in steps if s["step"] == "training"} == {False, True}
    assert SIZE[0] % 32 == 0 and SIZE[1] % 32 == 0 and TRAIN_SIZE[0] % 32 == 0
    assert sum(STEP_BUDGET.values()) <= budget <= 480, f"budget {budget} s vs steps {STEP_BUDGET}"


def training_step(
    device: torch.device,
    batch: int,
    checkpointing: bool,
    size: tuple[int, int] = TRAIN_SIZE,
    width: float = 1.0,
    steps: int = 3,
) -> dict[str, float]:
    """Median seconds of our training step, samples/s and peak memory (CUDA: allocator peak)."""
    import semattnet
    from semattnet.training.checkpointing import set_activation_checkpointing
    from semattnet.training.reference import make_adam, our_step

    net = semattnet.build_model("semattnet", width=width).to(device).train()
    if checkpointing:
        set_activation_checkpointing(net)
    opt = make_adam(net.parameters(), device, lr=1e-4)
    data = frame(batch, size, device) | {"gt": torch.rand(batch, 1, *size, device=device) * 80}
    result = latency(lambda: our_step(net, opt, data, device), device, steps)
    return {"seconds": result["median_s"], "samples_per_s": batch / result["median_s"], "peak_mib": result["peak_mib"]}


def run(args: argparse.Namespace) -> dict[str, Any]:
    import semattnet
    from semattnet.models.refinement import refine

    device = torch.device("cuda")
    start, rows = time.monotonic(), {"gpu": torch.cuda.get_device_name(device), "torch": torch.__version__}
    model = semattnet.build_model("semattnet", width=1.0).to(device).eval()
    x1, x8 = frame(1, SIZE, device), frame(8, SIZE, device)
    with torch.inference_mode():
        reference = model(**x1).refined_depth
    built: dict[str, Callable[..., Any]] = {}

    def left() -> bool:
        return time.monotonic() - start < args.budget

    for step in plan(device, args.train_batch):
        label = {k: v for k, v in step.items() if k not in ("what", "tol", "skip")}
        if step["skip"] or not left():
            rows.setdefault("skipped", []).append(label | {"why": step["skip"] or "time budget spent"})
            continue
        try:
            if step["step"] == "parity":
                built[step["backend"]] = fn = build(step["backend"], model, device, SIZE)
                err = parity(fn, reference, x1)
                rows.setdefault("parity", []).append(label | {"max_rel_diff": err, "ok": err <= step["tol"]})
            elif step["step"] == "latency" and step["backend"] in built:
                fn, x = built[step["backend"]], x1 if step["batch"] == 1 else x8
                if step["backend"] in ("tensorrt",) and step["batch"] != 1:
                    raise RuntimeError("the TensorRT engine is built for batch 1")
                rows.setdefault("latency", []).append(label | latency(lambda: fn(**x), device, args.repeats))  # noqa: B023
            elif step["step"] == "propagation":
                rows["propagation"] = _propagation(model, x1, device, args.repeats, refine)
            elif step["step"] == "training":
                measured = training_step(device, step["batch"], step["checkpointing"])
                rows.setdefault("training", []).append(label | measured)
        except Exception as e:  # a failing backend is a result, not the end of the script
            rows.setdefault("failed", []).append(label | {"error": f"{type(e).__name__}: {e}".splitlines()[0]})
        print(json.dumps(label), f"{time.monotonic() - start:.0f} s", flush=True)
    rows["seconds"] = time.monotonic() - start
    return rows


def _propagation(
    model: torch.nn.Module,
    x: dict[str, torch.Tensor],
    device: torch.device,
    repeats: int,
    propagate: Callable[..., Any],
) -> dict[str, Any]:
    """The propagation alone: eager (shifted), compiled and the authors' pad-and-sum, with parity."""
    from semattnet.inference.backends.compiled_propagation import compiled_propagation

    with torch.inference_mode():
        _, heads = model.forward_network(**x)
        n = model.config.iterations
        ref = propagate(heads, n, "naive")[1]
        fns = {
            "naive": lambda: propagate(heads, n, "naive"),
            "eager": lambda: propagate(heads, n, "pytorch"),
            "compiled": lambda: compiled_propagation()(heads, n),
        }
        out = {k: latency(f, device, repeats) for k, f in fns.items()}
        for k, f in fns.items():
            out[k]["max_rel_diff"] = float((f()[1] - ref).abs().max() / ref.abs().max())
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dry-run", action="store_true", help="print and check the plan (no GPU needed)")
    p.add_argument("--budget", type=float, default=450.0, help="seconds; later steps are skipped past it")
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--train-batch", type=int, default=8)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    steps = plan(torch.device("cuda"), args.train_batch)
    check_plan(steps, args.budget)
    for s in steps:
        print(json.dumps({k: v for k, v in s.items() if k != "what"}))
    print(f"plan ok: {len(steps)} steps, budget {args.budget:.0f} s; this machine: {device}")
    if args.dry_run:
        return 0
    if device.type != "cuda":
        print("no CUDA device here: nothing measured (not measured on a GPU)")
        return 1
    rows = run(args)
    print(json.dumps(rows, indent=1))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
