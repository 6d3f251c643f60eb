"""``run_demo``: synthetic scenes -> baselines -> live training -> the shipped reference -> report."""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._utils.device import resolve_device
from semattnet.apps.demo import figures as figs
from semattnet.apps.demo import reference as ref
from semattnet.apps.demo.recipe import LABELS, MODELS, RECIPE_NOTES, REFERENCE_KEY, DemoSettings, train_models
from semattnet.apps.demo.results import (
    comparisons,
    mean_over_seeds,
    verdict_sentences,
    with_seed_rows,
    write_results,
)
from semattnet.apps.experiment import HeldOut, complete_held_out, make_synthetic, score
from semattnet.baselines.classical import complete_classical
from semattnet.viz.report import write_report

__all__ = ["DemoResult", "make_empty", "run_demo", "train_reference_run"]


@dataclass
class DemoResult:
    out_dir: Path
    report_md: Path
    report_html: Path
    #: method -> group ("all", "shadowed", "unshadowed") -> KITTI metrics (leaderboard units), mean over seeds
    metrics: dict[str, dict[str, dict[str, float]]]
    steps: dict[str, dict[str, int]] = field(default_factory=dict)
    seconds: float = 0.0
    viewer_html: Path | None = None
    results_json: Path | None = None


def run_demo(
    out_dir: str | Path = "semattnet-demo",
    settings: DemoSettings | None = None,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
) -> DemoResult:
    """Run the demo into ``out_dir`` (refused if it holds files, unless ``overwrite``)."""
    s = settings or DemoSettings()
    t_start = time.perf_counter()
    out = Path(out_dir)
    make_empty(out, overwrite)
    device = resolve_device(s.device)
    torch.manual_seed(s.seed)
    h, w = s.size
    log(f"[1/5] generating {s.train_frames} training and {s.eval_frames} held-out scenes at {h}x{w} ...")
    held = make_synthetic(out / "data", s.train_frames, s.eval_frames, s.size, s.seed, style=s.style)
    log("[2/5] scoring the sparse input and the classical (non-learned) completion ...")
    base = _baselines(held)
    trained = train_models(s, device, out, held, log)  # [3/5] and [4/5]
    reference = _reference(s, held, device, log)
    if reference is not None:
        base[REFERENCE_KEY] = reference[0]
    order = ("sparse", "classical", *reversed([k for k, _, _ in MODELS]), *([REFERENCE_KEY] if reference else []))
    per_seed = {seed: {m: score((base | preds)[m], held) for m in order} for seed, preds in trained.per_seed.items()}
    metrics = mean_over_seeds(per_seed)
    log("[5/5] writing pictures, the report and the viewer ...")
    preds = base | trained.per_seed[s.training_seeds()[0]]
    figures = figs.figures(out / "pictures", held, preds, trained)
    viewer = figs.viewer(out, held, preds, trained, s.viewer_frames)
    seconds = time.perf_counter() - t_start
    setup: dict[str, Any] = {
        "device": str(device), "torch_threads": torch.get_num_threads(), "seconds": round(seconds, 1),
        "held_out": {"frames": len(held.names), "shadowed": sum(held.shadowed.values())},
        "settings": asdict(s), "steps": trained.steps, "seeds": list(s.training_seeds()),
        "recipe": {"live": list(RECIPE_NOTES)},
    }  # fmt: skip
    setup["comparisons"] = comparisons(metrics)
    setup["verdicts"] = verdict_sentences(setup["comparisons"], setup["seeds"])
    notes = list(RECIPE_NOTES)
    if reference is not None:
        setup["reference"] = reference[1] | {"comparisons": comparisons(metrics, REFERENCE_KEY)}
        setup["verdicts"] += verdict_sentences(setup["reference"]["comparisons"], setup["seeds"], REFERENCE_KEY)
        setup["recipe"]["reference"] = reference[1]["recipe_notes"]
        notes += reference[1]["recipe_notes"]
    (out / "metrics.json").write_text(json.dumps({"metrics": metrics, "setup": setup}, indent=2) + "\n")
    results = write_results(out / "results.json", per_seed, metrics, trained, setup)
    links = [("Interactive viewer of the held-out scenes (hover for depths, layers, 3D point cloud)", "viewer.html"),
             ("All numbers as JSON", "results.json")]  # fmt: skip
    table, labels = with_seed_rows(metrics, per_seed)
    md, html = write_report(out, table, labels, figures, setup | {"verdicts": setup["verdicts"] + notes}, links=links)
    _summarise(metrics, order, seconds, html, log)
    return DemoResult(out, md, html, metrics, trained.steps, seconds, viewer, results)


def _reference(
    s: DemoSettings, held: HeldOut, device: torch.device, log: Callable[[str], None]
) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
    """The shipped reference's refined depths on the held-out scenes and what results.json records of it."""
    if not s.reference:
        return None
    path = ref.REFERENCE_PATH
    if not path.is_file():
        log(f"(no reference checkpoint at {path}: skipped; `{ref.REFERENCE_COMMAND}` makes one)")
        return None
    log(f"[4/5] completing the held-out scenes with the shipped reference checkpoint ({path.name}) ...")
    model, info = ref.load_reference(path)
    preds = {n: o["refined_depth"] for n, o in complete_held_out(model, held, device).items()}
    record = {
        "label": LABELS[REFERENCE_KEY], "file": path.name, "bytes": path.stat().st_size,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(), "storage": ref.REFERENCE_STORAGE,
        "command": info.get("command", ref.REFERENCE_COMMAND), "recipe": info.get("recipe", {}),
        "recipe_notes": ref.recipe_notes(info.get("recipe", {})), "train_seconds": info.get("train_seconds"),
        "trained_on": info.get("machine"), "own_validation": info.get("val"),
    }  # fmt: skip
    return preds, record


def train_reference_run(
    out_dir: str | Path, overwrite: bool = False, device: str = "auto", log: Callable[[str], None] = print
) -> Path:
    """``semattnet demo --train-reference``: train the reference checkpoint in ``out_dir`` (refused if
    it holds files, unless ``overwrite``) and write ``out_dir/demo_reference.safetensors.gz``."""
    out = Path(out_dir)
    make_empty(out, overwrite)
    return ref.train_reference(out, out / ref.REFERENCE_PATH.name, device=resolve_device(device), log=log)


def make_empty(out: Path, overwrite: bool) -> None:
    """Create ``out``; if it holds files, empty it when ``overwrite``, else refuse."""
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{out} is not empty; pass --overwrite to replace it")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)


def _baselines(held: HeldOut) -> dict[str, dict[str, np.ndarray]]:
    """Predictions of the non-learned baselines, method -> scene -> depth: the sparse input itself, classical."""
    preds: dict[str, dict[str, np.ndarray]] = {"sparse": {}, "classical": {}}
    for n, smp in zip(held.names, held.samples, strict=True):
        preds["sparse"][n] = smp["sparse"][0].numpy()  # the devkit fills its holes when scoring
        preds["classical"][n] = complete_classical(smp["sparse"][None])[0, 0].numpy()
    return preds


def _summarise(
    metrics: dict[str, dict[str, dict[str, float]]],
    order: tuple[str, ...],
    seconds: float,
    html: Path,
    log: Callable[[str], None],
) -> None:
    """Log the held-out RMSE of every method and where the report is; fail if SemAttNet's RMSE is not finite."""
    best_base = min(metrics["sparse"]["all"]["rmse_mm"], metrics["classical"]["all"]["rmse_mm"])
    ours = metrics["semattnet"]["all"]["rmse_mm"]

    def short(k: str) -> str:
        return "SemAttNet reference (shipped)" if k == REFERENCE_KEY else LABELS[k].split(" (")[0]

    summary = ", ".join(f"{short(k)} {metrics[k]['all']['rmse_mm'] / 1000:.2f} m" for k in reversed(order))
    log(f"held-out RMSE: {summary} (SemAttNet {'beats' if ours < best_base else 'does not beat'} both baselines)")
    log(f"done in {seconds / 60:.1f} min. Report: {html.resolve()}")
    if not math.isfinite(ours):
        raise RuntimeError("the trained model produced no finite RMSE")
