"""The speed/accuracy frontier: every real-time variant and the paper model (widths 1/8 and 1/4) trained by the
recipe of the demo's reference checkpoints, scored on the demo's held-out scenes beside the classical completion.

Training half (a GPU machine; torch, numpy, click, safetensors, scipy, pillow and h5py suffice: nothing here
imports plotly, openvino or rosbags):

    python benchmarks/frontier.py --out frontier-run --device cuda

from the repository root, the package installed or ``PYTHONPATH=src``. Timing half (later, on the quiet 2-core
CPU; it reads the checkpoints of the training half when present), then the report:

    python benchmarks/frontier.py --out frontier-run --time --isa-cap AVX2
    python benchmarks/frontier.py --out frontier-run --report

(or ``--all``: the three in one go on one machine).

Recipe (:data:`semattnet.apps.demo.reference.REFERENCE_RECIPE`, the one ``semattnet-demo-ref-seed0`` was trained
with): 400 synthetic training scenes (data seed 1000) at 96x320, batch 4, Adam at 2e-3 with cosine schedules,
600 backbone steps, 60 refinement-initialisation steps (head at 5x), 200 full-model steps (backbone at lr / 4),
L1 + L2 loss; training seeds 0 and 1. Every variant gets the same recipe: the real-time ones at their registered
widths, the paper model at widths 1/8 and 1/4. Held-out scenes: the demo's (16 scenes, data seed 0, none seen
in training). Scores: RMSE, MAE, iRMSE, iMAE (means over scenes) and the AUSE of the model's uncertainty, per
seed and their mean.

Written to ``--out``: ``results.json`` (the recipe, the machine, every score) and per variant and seed its
weights, ``checkpoints/<variant>_seed<S>.safetensors`` (config in the metadata). ``--time`` adds ``timing.json``,
at ``--time-size`` (352x1216): the CPU named (model, threads, ISA flags); per variant its GMAC and parameters;
per variant and backend (:data:`BACKENDS`: torch float32 with BatchNorm folded, OpenVINO float32 and int8, each
built by the engine table, one backend after the other, the variants in turns, returning the refined depth:
:data:`DEPTH_ONLY`) the network + propagation's median ms and its ratio to the width-1/8 paper model (with
``--isa-cap AVX2`` also OpenVINO float32 with oneDNN's AVX2 kernels only, in a fresh process), and the memory
of one forward in a fresh process (:data:`MEMORY`); per variant the whole ``predict --stream`` frame on its
fastest backend (the library's frame loop on synthetic scenes as a folder input: its latency table); the
classical completion's ms; the float32 convolution peak measured at that size (GFLOP/s); and, with
``results.json`` there, each variant's int8 scores on the held-out scenes beside its float32 ones (``--variants``:
those variants are timed anew beside the reference, the others' entries kept from a ``timing.json`` of the same CPU
and size). ``--report``
writes the section "The real-time frontier" of ``docs/performance.md`` (between its markers) and
``docs/frontier.png`` from the two files (``benchmarks/frontier_report.py``).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib.util
import json
import statistics
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from frontier_report import METRICS
from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.device import resolve_device
from semattnet.apps.demo import uncertainty as unc
from semattnet.apps.demo.recipe import DemoSettings
from semattnet.apps.demo.reference import (
    REFERENCE_RECIPE,
    ReferenceRecipe,
    machine_line,
    package_reference,
    reference_for,
)
from semattnet.apps.experiment import (
    HeldOut,
    complete_held_out,
    load_held_out,
    make_synthetic,
    score_held_out,
    train_variant,
)
from semattnet.apps.timing import conv_peak_gflops
from semattnet.baselines.classical import complete_classical
from semattnet.models.registry import build_model, list_models, model_config
from semattnet.weights.checkpoint import load_checkpoint, load_weights, save_safetensors
from semattnet.weights.packed import SHIPPED

#: The docs folder the report writes into (``--docs``).
DOCS = Path(__file__).resolve().parents[1] / "docs"
#: The command of the full training run (results.json records it).
COMMAND = "python benchmarks/frontier.py --out frontier-run --device cuda"
PAPER = (("paper_w1_8", "semattnet", 0.125), ("paper_w1_4", "semattnet", 0.25))


def variants() -> list[tuple[str, str, float]]:
    """(key, registered model, width): the paper model at widths 1/8 and 1/4, then every real-time variant."""
    rt = [(name, name, model_config(name).width) for name in list_models() if model_config(name).realtime]
    return [*PAPER, *rt]


def train_one(
    work: Path,
    data: Path,
    recipe: ReferenceRecipe,
    name: str,
    width: float,
    device: torch.device,
    log: Callable[[str], None],
) -> Path:
    """One variant, one seed, by ``recipe``, on the synthetic tree ``data``: the trained full model's checkpoint."""
    return train_variant(work, data, recipe.variant(width, branches=3, model=name), device, log=log)


def load_model(path: Path) -> torch.nn.Module:
    ckpt = load_checkpoint(path)
    model = build_model(config=ckpt.config)
    load_weights(model, ckpt)
    return model.eval()


def trained(
    out: Path,
    key: str,
    seed: int,
    train: Callable[[], Path],
    log: Callable[[str], None],
    recipe: ReferenceRecipe | None = None,
) -> torch.nn.Module:
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
    """The shipped demo reference of ``seed`` when it is variant ``key`` trained by ``recipe``
    (:func:`~semattnet.apps.demo.reference.reference_for`), else None."""
    return reference_for(recipe, seed) if key == "paper_w1_8" and recipe is not None else None


def _scores(preds: dict[str, np.ndarray], held: HeldOut) -> dict[str, float]:
    return {k: float(score_held_out(preds, held)["all"][k]) for k in METRICS}


def _mean(per_seed: dict[str, dict[str, float]]) -> dict[str, float]:
    keys = next(iter(per_seed.values())).keys()
    return {k: statistics.fmean(s[k] for s in per_seed.values()) for k in keys}


def train_and_score(
    out: Path,
    recipe: ReferenceRecipe,
    seeds: Sequence[int],
    held: HeldOut,
    device: torch.device,
    keys: Sequence[str] | None,
    log: Callable[[str], None],
) -> dict[str, Any]:
    """Train every variant per seed, save its weights, score it; the classical completion beside them."""
    classical = {
        n: complete_classical(s["sparse"][None])[0, 0].numpy() for n, s in zip(held.names, held.samples, strict=True)
    }
    preds: unc.BySeed = {"classical": dict.fromkeys(seeds, classical)}
    uncs: unc.BySeed = {"classical": dict.fromkeys(seeds, unc.classical_uncertainties(held, classical))}
    results: dict[str, Any] = {"classical": {"scores": _scores(classical, held)}}
    for key, name, width in variants():
        if keys and key not in keys:
            continue
        per_seed = {}
        for seed in seeds:
            run = functools.partial(
                train_one,
                out / "runs" / f"{key}_seed{seed}",
                out / "data",
                dataclasses.replace(recipe, seed=seed),
                name,
                width,
                device,
                log,
            )
            model = trained(out, key, seed, run, log, recipe)
            outputs = complete_held_out(model, held, device)
            preds.setdefault(key, {})[seed] = {n: o["refined_depth"] for n, o in outputs.items()}
            uncs.setdefault(key, {})[seed] = {n: o["uncertainty"] for n, o in outputs.items()}
            per_seed[str(seed)] = _scores(preds[key][seed], held)
        params = sum(p.numel() for p in model.parameters())
        results[key] = {
            "model": name,
            "width": width,
            "params": params,
            "affinity": model.config.affinity,
            "per_seed": per_seed,
            "scores": _mean(per_seed),
        }
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
    held = synthetic(
        out / "held_out",
        2 if args.frames else demo.train_frames,
        2 if args.frames else demo.eval_frames,
        recipe.size,
        demo.seed,
        style=demo.style,
    )
    seeds = tuple(int(s) for s in args.seeds.split(","))
    keys = args.variants.split(",") if args.variants else None
    results = train_and_score(out, recipe, seeds, held, device, keys, log)
    _write_json(
        target,
        {
            "command": COMMAND,
            "recipe": dataclasses.asdict(recipe),
            "seeds": seeds,
            "device": str(device),
            "machine": machine_line(),
            "torch": torch.__version__,
            "seconds": round(time.perf_counter() - start, 1),
            "results": results,
        },
    )
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
    found = {
        "seed": m.get("seed"),
        "size": m.get("size"),
        "style": m.get("style"),
        "train": counts.get("train"),
        "val_select": counts.get("val_select"),
    }
    if found != wanted:
        raise InputError(f"{manifest}: written with {found}, this run needs {wanted}; use another --out")
    return load_held_out(root)


def _size(text: str, option: str = "--size") -> tuple[int, int]:
    h, _, w = text.lower().partition("x")
    if not (h.isdigit() and w.isdigit()):
        raise InputError(f"{option} must be HxW, e.g. 352x1216, got {text!r}")
    return int(h), int(w)


#: (name in timing.json, engine, precision): the backends timed, one after the other (OpenVINO's thread pool beside
#: torch's would slow both). int8 is the engine table's OpenVINO int8 (NNCF, calibrated on synthetic scenes).
BACKENDS = (("torch-f32", "torch", "f32"), ("openvino-f32", "openvino", "f32"), ("openvino-int8", "openvino", "int8"))
#: What the timed engines return: the refined depth, what a robot reads (``optimize_for_inference(outputs=)``: OpenVINO
#: compiles only what it needs; the torch engine computes every map regardless).
DEPTH_ONLY = ("refined_depth",)
#: ``--isa-cap``: the instruction sets oneDNN's kernels may be capped at (``ONEDNN_MAX_CPU_ISA``), e.g. an AVX-512
#: CPU timed with the AVX2 kernels an AVX2-only CPU runs (same cores, clocks and caches: an estimate, not that CPU).
ISA_CAPS = ("AVX2", "AVX512_CORE")
#: How timing.json's peak_mb is measured.
MEMORY = (
    "one forward in a fresh process per variant and backend, its engine built: the resident set's high-water "
    "mark (VmHWM, reset by /proc/self/clear_refs) and its growth over VmRSS before the forward"
)
#: Frames of the whole-frame run (``predict --stream``'s loop); their median is robust to the first one's warm-up.
STREAM_FRAMES = 6


def machine() -> dict[str, Any]:
    """The CPU named: its model, the threads torch uses, its notable ISA flags (avx2, avx512*, amx*:
    :data:`semattnet._utils.cpu.SHOWN_FLAGS`)."""
    from semattnet._utils.cpu import SHOWN_FLAGS, cpu_flags, cpu_model

    isa = [f for f in SHOWN_FLAGS if f in cpu_flags()]
    return {"cpu": cpu_model(), "threads": torch.get_num_threads(), "isa": isa}


def _backends() -> list[tuple[str, str, str]]:
    """The :data:`BACKENDS` this machine has (OpenVINO installed; int8 also needs nncf)."""
    from semattnet.inference.backends import get_engine

    have_nncf = importlib.util.find_spec("nncf") is not None
    return [(n, b, p) for n, b, p in BACKENDS if get_engine(b).installed() and (p != "int8" or have_nncf)]


def _timed_models(out: Path, keys: Sequence[str] | None) -> dict[str, torch.nn.Module]:
    """Every variant (``keys``: these and the width-1/8 paper model, the reference): :func:`_variant_model`."""
    return {key: _variant_model(out, key) for key, _, _ in variants() if not keys or key in (*keys, "paper_w1_8")}


def _counts(models: dict[str, torch.nn.Module], size: tuple[int, int]) -> dict[str, dict[str, float]]:
    """Per variant: GMAC of one frame of ``size`` (:func:`~semattnet.models.macs.count_macs`) and parameters."""
    from bench_rt import frame
    from semattnet.models.macs import count_macs

    x = frame(size)
    return {k: {"gmac": count_macs(m, x), "params": sum(p.numel() for p in m.parameters())} for k, m in models.items()}


def _classical_ms(size: tuple[int, int], repeats: int) -> float:
    """The classical completion's time on one frame of ``size`` (median of ``repeats`` after a warm-up)."""
    from bench_rt import frame

    sparse = frame(size)["sparse"]
    return 1000 * statistics.median(_in_turns({"classical": lambda: complete_classical(sparse)}, repeats)["classical"])


def _variant_model(out: Path, key: str) -> torch.nn.Module:
    """Seed 0 of variant ``key``: its trained weights where the training half left them, else random ones (speed
    and memory do not depend on the weights)."""
    name, width = next((n, w) for k, n, w in variants() if k == key)
    path = out / "checkpoints" / f"{key}_seed0.safetensors"
    if path.is_file():
        return load_model(path)
    with torch.random.fork_rng():  # the same weights in every process: their exported engines are cached once
        torch.manual_seed(0)
        return build_model(name, width=width).eval()


def forward_memory(out: Path, key: str, backend: str, size: tuple[int, int]) -> dict[str, float]:
    """In this process (a fresh one: :func:`_memory`): variant ``key``'s engine of ``backend`` built, then one
    forward at ``size``: the resident set's high-water mark during it (reset through Linux's
    ``/proc/self/clear_refs`` once the engine is built, :func:`~semattnet.apps.timing.peak_memory`) and its growth
    over the resident set before, in MB."""
    from bench_rt import frame
    from semattnet.apps.timing import peak_memory, status_mib
    from semattnet.inference.backends import optimize_for_inference

    engine, precision = next((e, p) for n, e, p in BACKENDS if n == backend)
    net = optimize_for_inference(
        _variant_model(out, key), backend=engine, size=size, precision=precision, outputs=DEPTH_ONLY
    )
    x = frame(size)
    before = status_mib("VmRSS")
    with torch.inference_mode(), peak_memory(torch.device("cpu")) as pm:
        net(**x)
    mb = 2**20 / 1e6
    return {"peak_mb": pm["peak_mib"] * mb, "growth_mb": (pm["peak_mib"] - before) * mb}


def _memory(out: Path, key: str, backend: str, size: tuple[int, int]) -> dict[str, float]:
    """:func:`forward_memory` in a fresh Python process (nothing of the other variants resident); NaN where that
    process fails (said in one line: the run goes on)."""
    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--out",
        str(out),
        "--memory-of",
        f"{key}/{backend}",
        "--time-size",
        f"{size[0]}x{size[1]}",
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:  # the times stay: one line, and no memory figure for this row
        print(f"[frontier] {key}/{backend}: the memory run failed: {(done.stderr.strip().splitlines() or ['?'])[-1]}")
        return {"peak_mb": float("nan"), "growth_mb": float("nan")}
    return {k: float(v) for k, v in json.loads(done.stdout.strip().splitlines()[-1]).items()}


def time_network(
    out: Path,
    models: dict[str, torch.nn.Module],
    size: tuple[int, int],
    repeats: int,
    log: Callable[[str], None] = print,
) -> dict[str, dict[str, float]]:
    """Network + propagation per variant and backend (``KEY/BACKEND`` -> ms, ratio to the width-1/8 paper model
    on that backend, peak and growth of the resident set in MB, :func:`forward_memory`): each backend's engines
    built by the engine table (:func:`~semattnet.inference.backends.optimize_for_inference`), its variants run in
    turns."""
    rows: dict[str, dict[str, float]] = {}
    for backend, _, _ in _backends():
        rows.update(time_backend(models, backend, size, repeats, log))
        for key in models:  # a fresh process each, once this backend's engines are built and cached
            rows[f"{key}/{backend}"].update(_memory(out, key, backend, size))
    return rows


def time_backend(
    models: dict[str, torch.nn.Module],
    backend: str,
    size: tuple[int, int],
    repeats: int,
    log: Callable[[str], None] = print,
) -> dict[str, dict[str, float]]:
    """``KEY/BACKEND`` -> ms and ratio to the width-1/8 paper model: the engines of one :data:`BACKENDS`
    row, returning :data:`DEPTH_ONLY`, run in turns."""
    from bench_rt import frame
    from semattnet.inference.backends import optimize_for_inference

    engine, precision = next((e, p) for n, e, p in BACKENDS if n == backend)
    x = frame(size)
    log(f"[frontier] {backend}: building the engines at {size[0]}x{size[1]} ...")
    nets = {
        key: functools.partial(
            optimize_for_inference(m, backend=engine, size=size, precision=precision, outputs=DEPTH_ONLY), **x
        )
        for key, m in models.items()
    }
    times = _in_turns(nets, repeats)
    rows: dict[str, dict[str, float]] = {}
    for key, t in times.items():
        ratio = statistics.median(a / b for a, b in zip(t, times["paper_w1_8"], strict=True))
        name, ms = f"{key}/{backend}", 1000 * statistics.median(t)
        rows[name] = {"ms": ms, "ratio": ratio}
        log(f"{name:40s} {ms:9.1f} ms  {ratio:6.3f} x paper@1/8")
    return rows


def time_capped(
    out: Path, keys: Sequence[str] | None, isa: str, size: tuple[int, int], repeats: int
) -> dict[str, dict[str, float]]:
    """OpenVINO float32 with oneDNN's kernels capped at ``isa`` (:data:`ISA_CAPS`), in a fresh process (the cap is
    read once, when the first kernel is made): rows ``KEY/openvino-f32-<isa>``; empty where that process fails
    (said in one line)."""
    import os

    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--out",
        str(out),
        "--network-of",
        "openvino-f32",
        "--time-size",
        f"{size[0]}x{size[1]}",
        "--repeats",
        str(repeats),
        "--variants",
        ",".join(keys or []),
    ]
    env = {**os.environ, "ONEDNN_MAX_CPU_ISA": isa}
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
    if done.returncode != 0:
        print(f"[frontier] openvino-f32 capped at {isa}: failed: {(done.stderr.strip().splitlines() or ['?'])[-1]}")
        return {}
    rows = json.loads(done.stdout.strip().splitlines()[-1])
    return {f"{k}-{isa.lower()}": v for k, v in rows.items()}


def write_stream_frames(folder: Path, size: tuple[int, int], count: int = STREAM_FRAMES) -> Any:
    """``count`` synthetic scenes at ``size`` (seeds 100, 101, ...) as a folder input (``rgb/``, ``sparse/``,
    ``semantic/`` PNGs, as ``predict`` reads them): its :class:`~semattnet.data.sources.FolderSource`."""
    from semattnet.data.io import write_depth, write_image
    from semattnet.data.sources import FolderSource
    from semattnet.synthetic import make_frame

    for sub in ("rgb", "sparse", "semantic"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    for i in range(count):
        name = f"{i:06d}.png"
        if all((folder / sub / name).is_file() for sub in ("rgb", "sparse", "semantic")):
            continue  # an earlier --time wrote it (the same seed: the same scene)
        f = make_frame(size[0], size[1], seed=100 + i)
        write_image(folder / "rgb" / name, f.rgb, overwrite=True)
        write_image(folder / "semantic" / name, f.semantic, overwrite=True)
        write_depth(folder / "sparse" / name, f.sparse, overwrite=True)
    return FolderSource.pair(folder / "rgb", folder / "sparse", folder / "semantic")


def time_stream(model: torch.nn.Module, backend: str, precision: str, source: Any, out: Path) -> dict[str, Any]:
    """The whole ``predict --stream`` frame: the library's frame loop (read ahead in a background thread, the
    network, the propagation, the depth and colour PNGs written) on ``source``; its latency table's per-frame
    median (the stages of one frame, summed), its throughput and each stage's median."""
    from semattnet.inference import DepthCompleter
    from semattnet.inference.backends import EngineSpec
    from semattnet.inference.options import OutputSpec, RunOptions
    from semattnet.inference.pipeline import check_frames
    from semattnet.inference.sinks import default_sinks
    from semattnet.inference.timing import StageTimes

    completer = DepthCompleter(model, EngineSpec(backend=backend, precision=precision, device="cpu"))
    timer = StageTimes()
    plan = check_frames(source, default_sinks(), out, OutputSpec(overwrite=True), RunOptions(prefetch=2))
    with warnings.catch_warnings():  # an untrained model's holes and clamped pixels, one line per frame
        warnings.simplefilter("ignore", UserWarning)
        plan.run(completer, timer=timer, log=lambda _: None)
    summary = timer.summary()
    stages = {k: round(v["median_ms"], 1) for k, v in summary["stages"].items() if "median_ms" in v}
    return {
        "backend": f"{backend}-{precision}",
        "frame_ms": summary["per_frame_median_ms"],
        "throughput_hz": summary["throughput_hz"],
        "stages_ms": stages,
    }


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


def int8_accuracy(out: Path, keys: Sequence[str], log: Callable[[str], None] = print) -> dict[str, Any]:
    """Every trained variant's scores on the held-out scenes in OpenVINO int8 (calibrated on the validation scenes
    of the training tree, never the held-out ones) beside its float32 scores of ``results.json``, over the seeds
    both have: ``key`` -> per_seed, scores (their mean), f32 (the same seeds' mean), change (int8 / f32 - 1)."""
    from semattnet.inference import DepthCompleter
    from semattnet.inference.backends import EngineSpec

    results = json.loads((out / "results.json").read_text())["results"]
    held = load_held_out(out / "held_out")
    found: dict[str, Any] = {}
    for key in keys:
        per_seed = {}
        for seed in results.get(key, {}).get("per_seed", {}):
            path = out / "checkpoints" / f"{key}_seed{seed}.safetensors"
            if not path.is_file():
                continue
            log(f"[frontier] {key}, seed {seed}: int8 on the held-out scenes ...")
            completer = DepthCompleter(
                load_model(path),
                EngineSpec(backend="openvino", precision="int8", device="cpu", calibration=out / "data"),
            )
            preds = {
                n: completer.run(s["rgb"][None], s["semantic"][None], s["sparse"][None]).refined_depth[0, 0].numpy()
                for n, s in zip(held.names, held.samples, strict=True)
            }
            per_seed[seed] = _scores(preds, held)
        if per_seed:
            f32 = _mean({s: results[key]["per_seed"][s] for s in per_seed})
            int8 = _mean(per_seed)
            found[key] = {
                "per_seed": per_seed,
                "scores": int8,
                "f32": f32,
                "change": {m: int8[m] / f32[m] - 1 for m in METRICS},
            }
    return found


def time_variants(
    out: Path,
    size: tuple[int, int],
    repeats: int,
    keys: Sequence[str] | None = None,
    log: Callable[[str], None] = print,
    isa_cap: str = "",
) -> Path:
    """The timing half, into ``timing.json``: network + propagation per variant and backend (:func:`time_network`),
    the whole ``predict --stream`` frame per variant on its fastest backend (:func:`time_stream`), and, where the
    training half left ``results.json`` and OpenVINO int8 runs here, the int8 scores (:func:`int8_accuracy`).
    ``keys``: these variants and the reference; ``isa_cap``: also OpenVINO float32 with oneDNN's kernels capped at
    that instruction set (:func:`time_capped`)."""
    models = _timed_models(out, keys)
    counts = _counts(models, size)
    rows = time_network(out, models, size, repeats, log)
    if isa_cap:
        rows.update(time_capped(out, keys, isa_cap, size, repeats))
    source = write_stream_frames(out / "timing" / "frames", size)
    frames = {}
    for key, model in models.items():
        best = min((rows[f"{key}/{b}"]["ms"], b) for b, _, _ in BACKENDS if f"{key}/{b}" in rows)[1]  # not capped
        engine, precision = next((e, p) for n, e, p in BACKENDS if n == best)
        log(f"[frontier] {key}: the whole --stream frame on {best} ...")
        frames[key] = time_stream(model, engine, precision, source, out / "timing" / f"stream_{key}")
    int8 = {}
    if (out / "results.json").is_file() and any(n == "openvino-int8" for n, _, _ in _backends()):
        int8 = int8_accuracy(out, list(models), log)
    target = out / "timing.json"
    classical = _classical_ms(size, repeats)
    peak = conv_peak_gflops(torch.device("cpu"), size)  # what the arithmetic alone would allow
    timing = {
        **machine(),
        "size": size,
        "repeats": repeats,
        "memory": MEMORY,
        "models": counts,
        "rows": rows,
        "classical_ms": classical,
        "conv_peak_gflops": peak,
        "frames": frames,
        "int8": int8,
    }
    _write_json(target, kept_from_earlier(target, timing, list(models)) if keys else timing)
    log(f"[frontier] wrote {target}")
    return target


def kept_from_earlier(path: Path, timing: dict[str, Any], timed: Sequence[str]) -> dict[str, Any]:
    """``timing`` (of the variants ``timed``) with the other variants' entries of the ``timing.json`` at ``path``
    kept, when that file was taken on this CPU at this size (``--variants`` re-times some variants of a full run);
    else ``timing`` alone."""
    if not path.is_file():
        return timing
    old, same = json.loads(path.read_text()), ("cpu", "threads", "isa", "size")
    if {k: old.get(k) for k in same} != json.loads(json.dumps({k: timing[k] for k in same})):
        return timing
    merged = dict(timing)
    for section in ("models", "frames", "int8"):
        merged[section] = {k: v for k, v in old.get(section, {}).items() if k not in timed} | timing[section]
    merged["rows"] = {k: v for k, v in old.get("rows", {}).items() if k.split("/")[0] not in timed} | timing["rows"]
    return merged


def main(argv: Sequence[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--device", default="auto", choices=("auto", "cuda", "cpu"))
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--variants", default="", help="comma-separated keys (default: all)")
    ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--time", action="store_true", help="the timing half (CPU)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--size", default="", help="HxW of the training scenes (default: the recipe's; checks only)")
    ap.add_argument("--time-size", default="352x1216", help="HxW the variants are timed at")
    ap.add_argument("--steps", default="", help="B,I,F steps instead of the recipe's (checks only)")
    ap.add_argument("--frames", type=int, default=0, help="training scenes instead of the recipe's (checks only)")
    ap.add_argument("--report", action="store_true", help="the docs' frontier section and plot from the two halves")
    ap.add_argument("--all", action="store_true", help="train and score, then --time, then --report")
    ap.add_argument("--docs", type=Path, default=DOCS, help="the folder of performance.md and frontier.png")
    ap.add_argument("--memory-of", default="", help=argparse.SUPPRESS)  # KEY/BACKEND: one forward_memory
    ap.add_argument("--network-of", default="", help=argparse.SUPPRESS)  # BACKEND: time_backend's rows as JSON
    ap.add_argument(
        "--isa-cap",
        default="",
        choices=("", *ISA_CAPS),
        help="with --time: also OpenVINO f32 with oneDNN's kernels capped at this ISA (e.g. AVX2)",
    )
    ap.add_argument("--ship", default="", help="KEY: package that variant's checkpoints into the package's assets")
    args = ap.parse_args(argv)
    keys = args.variants.split(",") if args.variants else None
    if args.ship:
        return ship(args.out, args.ship, tuple(int(s) for s in args.seeds.split(",")))[-1]
    if args.memory_of:
        key, backend = args.memory_of.split("/")
        print(json.dumps(forward_memory(args.out, key, backend, _size(args.time_size, "--time-size"))))
        return args.out
    if args.network_of:
        rows = time_backend(
            _timed_models(args.out, keys),
            args.network_of,
            _size(args.time_size, "--time-size"),
            args.repeats,
            log=lambda line: print(line, file=sys.stderr),
        )
        print(json.dumps(rows))
        return args.out
    if args.all:
        run_training(args)
    if args.time or args.all:
        time_variants(args.out, _size(args.time_size, "--time-size"), args.repeats, keys, isa_cap=args.isa_cap)
    if args.report or args.all:
        return report(args.out, args.docs)
    return args.out / "timing.json" if args.time else run_training(args)


def ship(
    out: Path, key: str, seeds: Sequence[int], assets: Path = SHIPPED, log: Callable[[str], None] = print
) -> list[Path]:
    """``--ship KEY``: each seed's trained checkpoint of variant ``key`` packed as the demo references are
    (:func:`~semattnet.apps.demo.reference.package_reference`: quantised, scored on the training tree's own
    validation scenes beside the classical completion, the recipe and command recorded) into ``assets`` as
    ``<key>_demo_seed<S>.safetensors.gz``."""
    held = load_held_out(out / "data")
    made = []
    for seed in seeds:
        ckpt = out / "checkpoints" / f"{key}_seed{seed}.safetensors"
        if not ckpt.is_file():
            raise InputError(f"{ckpt}: no trained checkpoint of {key}, seed {seed}; train it first")
        target = assets / f"{key}_demo_seed{seed}.safetensors.gz"
        made.append(
            package_reference(
                ckpt, held, target, dataclasses.replace(REFERENCE_RECIPE, seed=seed), log=log, command=COMMAND
            )
        )
    return made


def report(out: Path, docs: Path) -> Path:
    """``--report``: the section between the markers of ``docs/performance.md`` and ``docs/frontier.png``."""
    from frontier_report import write_report  # its plot imports matplotlib

    doc = write_report(out, docs / "performance.md", docs / "frontier.png")
    print(f"[frontier] wrote {doc} and {docs / 'frontier.png'}")
    return doc


if __name__ == "__main__":
    main()
