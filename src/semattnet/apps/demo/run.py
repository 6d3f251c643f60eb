"""``run_demo``: synthetic scenes -> baselines -> live training -> the shipped reference -> report."""

from __future__ import annotations

import dataclasses
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
from semattnet._utils.outputs import mark_tree
from semattnet.apps.demo import figures as figs
from semattnet.apps.demo import reference as ref
from semattnet.apps.demo import uncertainty as unc
from semattnet.apps.demo.recipe import (
    LABELS,
    MODEL_KEYS,
    RECIPE_NOTES,
    REFERENCE_KEY,
    DemoSettings,
    Trained,
    train_models,
)
from semattnet.apps.demo.results import (
    DemoSetup,
    ReferenceRecord,
    comparisons,
    mean_over_seeds,
    verdict_sentences,
    with_seed_rows,
    write_results,
)
from semattnet.apps.experiment import HeldOut, complete_held_out, make_synthetic, score_held_out
from semattnet.baselines.classical import complete_classical
from semattnet.cache import sha256_file
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
    order = ("sparse", "classical", *reversed(MODEL_KEYS), *([REFERENCE_KEY] if reference else []))
    runs = {m: {seed: score_held_out(preds[m], held) for seed, preds in trained.per_seed.items()} for m in MODEL_KEYS}
    runs |= {m: dict.fromkeys(trained.per_seed, score_held_out(base[m], held)) for m in base}  # the same for every seed
    if reference is not None:
        runs[REFERENCE_KEY] = {seed: score_held_out(preds, held) for seed, preds in reference[0].items()}
        base[REFERENCE_KEY] = next(iter(reference[0].values()))  # pictures and viewer: the first seed's
    metrics = {m: mean_over_seeds(runs[m]) for m in order}
    log("[5/5] writing pictures, the report and the viewer ...")
    preds = base | trained.per_seed[s.training_seeds()[0]]
    figures = figs.figures(out / "pictures", held, preds, trained)
    unc_scores = _uncertainty(held, base, trained, reference)
    unc_figure, unc_lines = unc.uncertainty_report(unc_scores, out / "pictures")
    viewer = figs.viewer(out, held, preds, trained, s.viewer_frames)
    seconds = time.perf_counter() - t_start
    setup, notes = _setup(s, device, seconds, held, trained, metrics, unc_scores, unc_lines, reference)
    (out / "metrics.json").write_text(json.dumps({"metrics": metrics, "setup": setup}, indent=2) + "\n")
    results = write_results(out / "results.json", runs, metrics, trained, setup)
    links = [
        ("Interactive viewer of the held-out scenes (hover for depths, layers, 3D point cloud)", "viewer.html"),
        ("All numbers as JSON", "results.json"),
    ]
    table, labels = with_seed_rows(metrics, runs)
    md, html = write_report(
        out, table, labels, [*figures, unc_figure], setup | {"verdicts": setup["verdicts"] + notes}, links=links
    )
    _summarise(metrics, order, seconds, html, log)
    mark_tree(out, "demo", True)
    return DemoResult(out, md, html, metrics, trained.steps, seconds, viewer, results)


def _setup(
    s: DemoSettings,
    device: torch.device,
    seconds: float,
    held: HeldOut,
    trained: Trained,
    metrics: dict[str, dict[str, dict[str, float]]],
    unc_scores: dict[str, Any],
    unc_lines: list[str],
    reference: tuple[dict[int, dict[str, np.ndarray]], ReferenceRecord, dict[int, dict[str, np.ndarray]]] | None,
) -> tuple[DemoSetup, list[str]]:
    """What the report says of the run (device, settings, steps, seeds, comparisons and verdicts, the uncertainty's
    scores, the recipes) and its notes."""
    setup: DemoSetup = {
        "device": str(device),
        "torch_threads": torch.get_num_threads(),
        "seconds": round(seconds, 1),
        "held_out": {"frames": len(held.names), "shadowed": sum(held.shadowed.values())},
        "settings": asdict(s),
        "steps": trained.steps,
        "seeds": list(s.training_seeds()),
        "recipe": {"live": list(RECIPE_NOTES)},
    }
    setup["comparisons"] = comparisons(metrics)
    setup["verdicts"] = verdict_sentences(setup["comparisons"], setup["seeds"])
    setup["uncertainty"] = unc_scores
    notes = [*unc_lines, *RECIPE_NOTES]
    if reference is not None:
        setup["reference"] = reference[1] | {"comparisons": comparisons(metrics, REFERENCE_KEY)}
        setup["verdicts"] += verdict_sentences(
            setup["reference"]["comparisons"], setup["seeds"], REFERENCE_KEY, reference[1]["seeds"]
        )
        setup["recipe"]["reference"] = reference[1]["recipe_notes"]
        notes += reference[1]["recipe_notes"]
    return setup, notes


def _reference(
    s: DemoSettings, held: HeldOut, device: torch.device, log: Callable[[str], None]
) -> tuple[dict[int, dict[str, np.ndarray]], ReferenceRecord, dict[int, dict[str, np.ndarray]]] | None:
    """Per training seed, the shipped reference's refined depths on the held-out scenes, what results.json
    records of the files, and per seed the depths' uncertainty (None when disabled or when no file is shipped)."""
    files = ref.shipped_references() if s.reference else {}
    if not files:
        if s.reference:
            log(f"(no reference checkpoint in {ref.REFERENCE_PATH.parent}: skipped; `{ref.REFERENCE_COMMAND}`)")
        return None
    preds: dict[int, dict[str, np.ndarray]] = {}
    uncs: dict[int, dict[str, np.ndarray]] = {}
    records: list[dict[str, object]] = []
    info: dict[str, Any] = {}
    for seed, path in files.items():
        log(f"[4/5] completing the held-out scenes with the shipped reference checkpoint ({path.name}) ...")
        model, info = ref.load_reference(path)
        outputs = complete_held_out(model, held, device)
        preds[seed] = {n: o["refined_depth"] for n, o in outputs.items()}
        uncs[seed] = {n: o["uncertainty"] for n, o in outputs.items()}
        records.append(
            {
                "seed": seed,
                "file": path.name,
                "bytes": path.stat().st_size,
                "sha256": sha256_file(path),
                "train_seconds": info.get("train_seconds"),
                "trained_on": info.get("machine"),
                "own_validation": info.get("val"),
            }
        )
    recipe = {k: v for k, v in info.get("recipe", {}).items() if k != "seed"}
    record = ReferenceRecord(
        label=LABELS[REFERENCE_KEY],
        seeds=list(files),
        files=records,
        storage=ref.REFERENCE_STORAGE,
        command=info.get("command", ref.REFERENCE_COMMAND),
        recipe=recipe,
        recipe_notes=ref.recipe_notes(info.get("recipe", {})),
    )
    return preds, record, uncs


def _uncertainty(
    held: HeldOut,
    base: dict[str, dict[str, np.ndarray]],
    trained: Trained,
    reference: tuple[dict[int, dict[str, np.ndarray]], ReferenceRecord, dict[int, dict[str, np.ndarray]]] | None,
) -> dict[str, dict[str, object]]:
    """AUSE / AURG of each method's uncertainty (:mod:`semattnet.apps.demo.uncertainty`): the classical
    completion (the same for every seed), the live models per seed and the reference checkpoints per seed."""
    seeds = list(trained.per_seed)
    classical = unc.classical_uncertainties(held, base["classical"])
    preds: unc.BySeed = {"classical": dict.fromkeys(seeds, base["classical"])}
    uncs: unc.BySeed = {"classical": dict.fromkeys(seeds, classical)}
    for key in MODEL_KEYS:
        preds[key] = {seed: trained.per_seed[seed][key] for seed in seeds}
        uncs[key] = {seed: trained.uncertainty[seed][key] for seed in seeds}
    if reference is not None:
        preds[REFERENCE_KEY], uncs[REFERENCE_KEY] = reference[0], reference[2]
    return unc.score_uncertainty(preds, uncs, held)


def train_reference_run(
    out_dir: str | Path,
    overwrite: bool = False,
    device: str = "auto",
    log: Callable[[str], None] = print,
    seeds: tuple[int, ...] = ref.REFERENCE_SEEDS,
    semantic_dropout: float = 0.0,
) -> list[Path]:
    """``semattnet demo --train-reference``: train one reference checkpoint per seed in ``out_dir``
    (refused if it holds files, unless ``overwrite``), writing ``out_dir/demo_reference_seed{S}.safetensors.gz``;
    ``semantic_dropout``: the recipe's share of frames trained with the fallback semantic map."""
    out = Path(out_dir)
    make_empty(out, overwrite)
    recipes = [
        dataclasses.replace(ref.REFERENCE_RECIPE, seed=seed, semantic_dropout=semantic_dropout) for seed in seeds
    ]
    paths = [
        ref.train_reference(
            out / f"seed{r.seed}", ref.reference_path(r.seed, out), r, device=resolve_device(device), log=log
        )
        for r in recipes
    ]
    mark_tree(out, "demo --train-reference", True)
    return paths


def make_empty(out: Path, overwrite: bool) -> None:
    """Create ``out`` with the demo's marker (:data:`~semattnet._utils.outputs.TREE_MARKER`); if it holds files,
    empty it when ``overwrite`` and it is an earlier demo's folder (its marker), else refuse."""
    from semattnet._utils.outputs import Output, check_outputs, mark_tree

    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{out} is not empty; pass --overwrite to replace it")
        check_outputs([], [Output("--out", out, "tree")], overwrite)  # never a user's folder
        shutil.rmtree(out)
    mark_tree(out, "demo", False, resume="run the demo again with --overwrite")


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
