"""The speed/accuracy frontier: every real-time variant and the paper model (widths 1/8 and 1/4) trained by the
recipe of the demo's reference checkpoints, scored on the demo's held-out scenes beside the classical completion.

Training half (a GPU machine; torch, numpy, click, safetensors, scipy, pillow and h5py suffice: nothing here
imports plotly, openvino or rosbags):

    python benchmarks/frontier.py --out frontier-run --device cuda

from the repository root, the package installed or ``PYTHONPATH=src``. Timing half (later, on the 2-core CPU;
it reads the checkpoints of the training half when present):

    python benchmarks/frontier.py --out frontier-run --time

Recipe (:data:`semattnet.apps.demo.reference.REFERENCE_RECIPE`, the one ``semattnet-demo-ref-seed0`` was trained
with): 400 synthetic training scenes (data seed 1000) at 96x320, batch 4, Adam at 2e-3 with cosine schedules,
600 backbone steps, 60 refinement-initialisation steps (head at 5x), 200 full-model steps (backbone at lr / 4),
L1 + L2 loss; training seeds 0 and 1. Every variant gets the same recipe: the real-time ones at their registered
widths, the paper model at widths 1/8 and 1/4. Held-out scenes: the demo's (16 scenes, data seed 0, none seen
in training). Scores: RMSE, MAE, iRMSE, iMAE (means over scenes) and the AUSE of the model's uncertainty, per
seed and their mean.

Written to ``--out``: ``results.json`` (the recipe, the machine, every score) and per variant and seed its
weights, ``checkpoints/<variant>_seed<S>.safetensors`` (config in the metadata). ``--time`` adds
``timing.json``: the network and the propagation at 352x1216 in torch float32 (BatchNorm folded) and, where
OpenVINO imports, in OpenVINO float32; each variant as a ratio to the width-1/8 paper model on the same
backend, in turns.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.device import resolve_device
from semattnet.apps.demo import uncertainty as unc
from semattnet.apps.demo.recipe import DemoSettings
from semattnet.apps.demo.reference import (
    REFERENCE_RECIPE,
    ReferenceRecipe,
    load_reference,
    machine_line,
    shipped_references,
)
from semattnet.apps.experiment import (
    HeldOut,
    complete_held_out,
    load_held_out,
    make_synthetic,
    score,
    train_variant,
)
from semattnet.baselines.classical import complete_classical
from semattnet.models.registry import build_model, list_models, model_config
from semattnet.weights.checkpoint import load_checkpoint, load_weights, save_safetensors

#: The command of the full training run (results.json records it).
COMMAND = "python benchmarks/frontier.py --out frontier-run --device cuda"
METRICS = ("rmse", "mae", "irmse", "imae")
PAPER = (("paper_w1_8", "semattnet", 0.125), ("paper_w1_4", "semattnet", 0.25))


def variants() -> list[tuple[str, str, float]]:
    """(key, registered model, width): the paper model at widths 1/8 and 1/4, then every real-time variant."""
    rt = [(name, name, model_config(name).width) for name in list_models() if model_config(name).realtime]
    return [*PAPER, *rt]


def train_one(work: Path, data: Path, recipe: ReferenceRecipe, name: str, width: float, device: torch.device,
              log: Callable[[str], None]) -> Path:  # fmt: skip
    """One variant, one seed, by ``recipe``, on the synthetic tree ``data``: the trained full model's checkpoint."""
    r = recipe
    return train_variant(work, data, r.backbone_steps, r.full_steps, size=r.size, width=width,
                         batch_size=r.batch_size, lr=r.lr, seed=r.seed, device=device, log=log,
                         refine_init_steps=r.refine_init_steps, head_lr_factor=r.head_lr_factor, loss=r.loss,
                         semantic_dropout=r.semantic_dropout, branches=3, model=name)  # fmt: skip


def load_model(path: Path) -> torch.nn.Module:
    ckpt = load_checkpoint(path)
    model = build_model(config=ckpt.config)
    load_weights(model, ckpt)
    return model.eval()


def trained(out: Path, key: str, seed: int, train: Callable[[], Path], log: Callable[[str], None],
            recipe: ReferenceRecipe | None = None) -> torch.nn.Module:  # fmt: skip
    """The variant's model of ``seed``: its saved weights when an earlier run left them (a run resumes variant by
    variant), else the shipped demo reference of that seed when ``recipe`` is the one it was trained by (the
    width-1/8 paper model: not trained twice), else trained by ``train`` and saved first."""
    saved = out / "checkpoints" / f"{key}_seed{seed}.safetensors"
    if saved.is_file():
        log(f"[frontier] {key}, seed {seed}: trained earlier ({saved})")
        return load_model(saved)
    if (shipped := shipped_reference(key, seed, recipe)) is not None:
        log(f"[frontier] {key}, seed {seed}: the shipped reference {shipped.name}, trained by this recipe")
        save_safetensors(load_checkpoint(shipped), saved)
        return load_model(saved)
    log(f"[frontier] {key}, seed {seed}: training ...")
    save_safetensors(load_checkpoint(train()), saved)
    return load_model(saved)


def shipped_reference(key: str, seed: int, recipe: ReferenceRecipe | None) -> Path | None:
    """The shipped demo reference of ``seed`` when it is variant ``key`` trained by ``recipe`` (same recipe but the
    seed, as its record says), else None. It ships quantised to 63 levels per tensor: its scores are those of
    the file users get."""
    if key != "paper_w1_8" or recipe is None or seed not in shipped_references():
        return None
    path = shipped_references()[seed]
    recorded = load_reference(path)[1].get("recipe", {})
    wanted = {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(recipe).items()}
    same = all(recorded.get(k, getattr(REFERENCE_RECIPE, k)) == v for k, v in wanted.items() if k != "seed")
    return path if same and recorded.get("seed") == seed else None


def _scores(preds: dict[str, np.ndarray], held: HeldOut) -> dict[str, float]:
    return {k: float(score(preds, held)["all"][k]) for k in METRICS}


def _mean(per_seed: dict[str, dict[str, float]]) -> dict[str, float]:
    keys = next(iter(per_seed.values())).keys()
    return {k: statistics.fmean(s[k] for s in per_seed.values()) for k in keys}


def train_and_score(out: Path, recipe: ReferenceRecipe, seeds: Sequence[int], held: HeldOut, device: torch.device,
                    keys: Sequence[str] | None, log: Callable[[str], None]) -> dict[str, Any]:  # fmt: skip
    """Train every variant per seed, save its weights, score it; the classical completion beside them."""
    classical = {n: complete_classical(s["sparse"][None])[0, 0].numpy()
                 for n, s in zip(held.names, held.samples, strict=True)}  # fmt: skip
    preds: unc.BySeed = {"classical": dict.fromkeys(seeds, classical)}
    uncs: unc.BySeed = {"classical": dict.fromkeys(seeds, unc.classical_uncertainties(held, classical))}
    results: dict[str, Any] = {"classical": {"scores": _scores(classical, held)}}
    for key, name, width in variants():
        if keys and key not in keys:
            continue
        per_seed = {}
        for seed in seeds:
            run = functools.partial(train_one, out / "runs" / f"{key}_seed{seed}", out / "data",
                                    dataclasses.replace(recipe, seed=seed), name, width, device, log)  # fmt: skip
            model = trained(out, key, seed, run, log, recipe)
            outputs = complete_held_out(model, held, device)
            preds.setdefault(key, {})[seed] = {n: o["refined_depth"] for n, o in outputs.items()}
            uncs.setdefault(key, {})[seed] = {n: o["uncertainty"] for n, o in outputs.items()}
            per_seed[str(seed)] = _scores(preds[key][seed], held)
        params = sum(p.numel() for p in model.parameters())
        results[key] = {"model": name, "width": width, "params": params, "per_seed": per_seed,
                        "scores": _mean(per_seed)}  # fmt: skip
    for key, ause in unc.score_uncertainty(preds, uncs, held).items():
        results[key]["uncertainty"] = {k: v for k, v in ause.items() if k not in ("curves", "label")}
    return results


def _write_json(path: Path, payload: dict[str, Any]) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(payload, indent=1, default=str) + "\n")


def run_training(args: argparse.Namespace, log: Callable[[str], None] = print) -> Path:
    """The training half: data, every variant and seed, ``results.json``; refuses to overwrite one."""
    out: Path = args.out
    target = out / "results.json"
    if target.exists() and not args.overwrite:
        raise InputError(f"{target} exists; pass --overwrite to replace it")
    recipe = REFERENCE_RECIPE
    if args.steps:
        b, i, f = (int(v) for v in args.steps.split(","))
        recipe = dataclasses.replace(recipe, backbone_steps=b, refine_init_steps=i, full_steps=f)
    if args.frames:
        recipe = dataclasses.replace(recipe, train_frames=args.frames, val_frames=2, batch_size=2)
    if args.size:
        recipe = dataclasses.replace(recipe, size=_size(args.size))
    demo = DemoSettings()
    device = resolve_device(args.device)
    start = time.perf_counter()
    synthetic(out / "data", recipe.train_frames, recipe.val_frames, recipe.size, recipe.data_seed, recipe.style)
    held = synthetic(out / "held_out", 2 if args.frames else demo.train_frames, 2 if args.frames else
                     demo.eval_frames, recipe.size, demo.seed, style=demo.style)  # fmt: skip
    seeds = tuple(int(s) for s in args.seeds.split(","))
    keys = args.variants.split(",") if args.variants else None
    results = train_and_score(out, recipe, seeds, held, device, keys, log)
    _write_json(target, {"command": COMMAND, "recipe": dataclasses.asdict(recipe), "seeds": seeds,
                         "device": str(device), "machine": machine_line(), "torch": torch.__version__,
                         "seconds": round(time.perf_counter() - start, 1), "results": results})  # fmt: skip
    log(f"[frontier] wrote {target}")
    return target


def synthetic(root: Path, frames: int, eval_frames: int, size: tuple[int, int], seed: int, style: str) -> HeldOut:
    """The synthetic tree at ``root``: read back when an earlier run wrote it with these settings (the generator
    is deterministic), else written; one that differs is refused in one line."""
    manifest = root / "scenes.json"
    if not manifest.is_file():
        return make_synthetic(root, frames, eval_frames, size, seed, style)
    m = json.loads(manifest.read_text())
    wanted = {"seed": seed, "size": list(size), "style": style, "train": frames, "val_select": eval_frames}
    counts = m.get("counts", {})
    found = {"seed": m.get("seed"), "size": m.get("size"), "style": m.get("style"), "train": counts.get("train"),
             "val_select": counts.get("val_select")}  # fmt: skip
    if found != wanted:
        raise InputError(f"{manifest}: written with {found}, this run needs {wanted}; use another --out")
    return load_held_out(root)


def _size(text: str) -> tuple[int, int]:
    h, _, w = text.lower().partition("x")
    if not (h.isdigit() and w.isdigit()):
        raise InputError(f"--size must be HxW, e.g. 352x1216, got {text!r}")
    return int(h), int(w)


def time_variants(out: Path, size: tuple[int, int], repeats: int, keys: Sequence[str] | None = None,
                  log: Callable[[str], None] = print) -> Path:  # fmt: skip
    """The timing half: torch float32 (BatchNorm folded), then, where it imports, OpenVINO float32; each backend's
    variants in turns, as ratios to the width-1/8 paper model on the same backend. The backends run one after the
    other: OpenVINO's own thread pool beside torch's would slow both. ``keys``: these variants and the reference."""
    from bench_rt import cpu_name, frame
    from semattnet.models.bn_folding import fold_batchnorm

    x = frame(size)
    models = {}
    for key, name, width in variants():
        if keys and key not in (*keys, "paper_w1_8"):
            continue
        path = out / "checkpoints" / f"{key}_seed0.safetensors"
        models[key] = fold_batchnorm(load_model(path) if path.is_file() else build_model(name, width=width).eval())
    rows: dict[str, dict[str, float]] = {}
    backends: dict[str, Callable[[torch.nn.Module], Callable[[], object] | None]] = {
        "torch-f32": lambda m: lambda: m(**x),
        "openvino-f32": lambda m: _openvino(m, x),
    }
    for backend, make in backends.items():
        nets = {key: fn for key, m in models.items() if (fn := make(m)) is not None}
        if not nets:
            continue
        times = _in_turns(nets, repeats)
        ref = times["paper_w1_8"]
        for key, t in times.items():
            ratio = statistics.median(a / b for a, b in zip(t, ref, strict=True))
            rows[f"{key}/{backend}"] = {"ms": 1000 * statistics.median(t), "ratio": ratio}
            log(f"{key + '/' + backend:32s} {1000 * statistics.median(t):9.1f} ms  {ratio:6.3f} x paper@1/8")
    target = out / "timing.json"
    _write_json(target, {"cpu": cpu_name(), "size": size, "repeats": repeats, "rows": rows})
    return target


def _in_turns(nets: dict[str, Callable[[], object]], repeats: int) -> dict[str, list[float]]:
    times: dict[str, list[float]] = {k: [] for k in nets}
    with torch.inference_mode():
        for fn in nets.values():
            fn()  # warm-up
        for _ in range(repeats):
            for k, fn in nets.items():
                start = time.perf_counter()
                fn()
                times[k].append(time.perf_counter() - start)
    return times


def _openvino(model: torch.nn.Module, x: dict[str, torch.Tensor]) -> Callable[[], object] | None:
    """The whole model (network and propagation) compiled by OpenVINO in float32, or None without OpenVINO."""
    try:
        import openvino as ov
    except ImportError:
        return None
    inputs = (x["rgb"], x["semantic"], x["sparse"])
    with torch.no_grad():
        compiled = ov.compile_model(ov.convert_model(_Depth(model), example_input=inputs), "CPU",
                                    {"INFERENCE_PRECISION_HINT": "f32", "PERFORMANCE_HINT": "LATENCY"})  # fmt: skip
    return lambda: compiled(list(inputs))


class _Depth(torch.nn.Module):
    """The final depth alone (what a converter traces)."""

    def __init__(self, model: torch.nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, rgb: torch.Tensor, semantic: torch.Tensor, sparse: torch.Tensor) -> torch.Tensor:
        return self.model(rgb, semantic, sparse).depth


def main(argv: Sequence[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--device", default="auto", choices=("auto", "cuda", "cpu"))
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--variants", default="", help="comma-separated keys (default: all)")
    ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--time", action="store_true", help="the timing half (CPU)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--size", default="", help="HxW: training scenes (default: the recipe's); --time: 352x1216")
    ap.add_argument("--steps", default="", help="B,I,F steps instead of the recipe's (checks only)")
    ap.add_argument("--frames", type=int, default=0, help="training scenes instead of the recipe's (checks only)")
    args = ap.parse_args(argv)
    if args.time:
        keys = args.variants.split(",") if args.variants else None
        return time_variants(args.out, _size(args.size or "352x1216"), args.repeats, keys)
    return run_training(args)


if __name__ == "__main__":
    main()
