"""The demo's numbers: means over seeds, the report's table, the comparisons and ``results.json``."""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path
from typing import TypedDict

import numpy as np
import torch

from semattnet.apps.demo.recipe import LABELS, MODEL_KEYS, REFERENCE_KEY, Trained
from semattnet.viz.report import ReportSetup

__all__ = [
    "COMPARED",
    "DEMO_METRICS",
    "RESULTS_SCHEMA",
    "DemoSetup",
    "Machine",
    "ReferenceRecord",
    "Runs",
    "comparisons",
    "machine",
    "mean_over_seeds",
    "record",
    "verdict_sentences",
    "with_seed_rows",
    "write_results",
]

RESULTS_SCHEMA = "semattnet.demo.results/2"


class _ReferenceFacts(TypedDict):
    label: str
    seeds: list[int]
    files: list[dict[str, object]]  # per seed: file, bytes, sha256, what its own record says
    storage: str
    command: str
    recipe: dict[str, object]
    recipe_notes: list[str]


class ReferenceRecord(_ReferenceFacts, total=False):
    """What the demo records of the shipped reference checkpoints (``results.json``'s ``reference``)."""

    comparisons: dict[str, dict[str, bool]]


class DemoSetup(ReportSetup, total=False):
    """The demo's run: the report's facts and what ``metrics.json`` / ``results.json`` record besides the metrics."""

    settings: dict[str, object]
    seeds: list[int]
    recipe: dict[str, list[str]]
    comparisons: dict[str, dict[str, bool]]
    uncertainty: dict[str, dict[str, object]]
    reference: ReferenceRecord


class Machine(TypedDict):
    """The machine a run was made on."""

    cpu: str
    cores: int | None
    torch: str
    python: str
    platform: str


#: The demo's comparisons: SemAttNet against each of these, on these metrics (issue 16's bar).
COMPARED: dict[str, tuple[str, ...]] = {"classical": ("rmse", "mae", "irmse", "imae"), "two_branch": ("rmse", "mae")}
DEMO_METRICS = ("rmse", "mae", "irmse", "imae")
_NAMES = {"rmse": "RMSE", "mae": "MAE", "irmse": "iRMSE", "imae": "iMAE"}
#: results.json metric name -> key of :meth:`~semattnet.evaluation.metrics.KittiMetrics.compute`.
_RESULT_KEYS = {"rmse": "rmse_mm", "mae": "mae_mm", "irmse": "irmse_per_km", "imae": "imae_per_km", "images": "images"}


#: method -> seed -> group -> KITTI metrics (:meth:`~semattnet.evaluation.metrics.KittiMetrics.compute`'s keys):
#: every score of a demo run.
Runs = dict[str, dict[int, dict[str, dict[str, float]]]]


def mean_over_seeds(runs: dict[int, dict[str, dict[str, float]]]) -> dict[str, dict[str, float]]:
    """group -> metric: the mean over seeds of one method's numbers (seed -> group -> metric)."""
    first = next(iter(runs.values()))
    return {
        group: {k: float(np.mean([run[group][k] for run in runs.values()])) for k in values}
        for group, values in first.items()
    }


def _learned() -> set[str]:
    """Methods with per-seed rows: the live models and the reference checkpoints."""
    return {*MODEL_KEYS, REFERENCE_KEY}


def with_seed_rows(
    metrics: dict[str, dict[str, dict[str, float]]], runs: Runs
) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, str]]:
    """The report's table: every method (learned ones: mean over seeds), then each learned model's seeds."""
    table, labels = {}, {}
    for method, groups in metrics.items():
        seeds = runs[method] if method in _learned() and len(runs[method]) > 1 else {}
        table[method] = groups
        labels[method] = LABELS[method] + (f", mean of {len(seeds)} seeds" if seeds else "")
        for seed, run in seeds.items():
            table[f"{method}@seed{seed}"] = run
            labels[f"{method}@seed{seed}"] = f"  {LABELS[method].split(' (')[0]}, seed {seed}"
    return table, labels


def comparisons(metrics: dict[str, dict[str, dict[str, float]]], ours: str = "semattnet") -> dict[str, dict[str, bool]]:
    """other method -> metric -> whether ``ours``'s held-out mean (over seeds) is lower (better)."""
    mine = record(metrics[ours])["all"]
    return {other: {k: mine[k] < record(metrics[other])["all"][k] for k in DEMO_METRICS} for other in COMPARED}


def _mean_of(seeds: list[int]) -> str:
    """How a headline over ``seeds`` is named: mean of seeds 0, 1; or seed 0 for one."""
    return f"mean of seeds {', '.join(map(str, seeds))}" if len(seeds) > 1 else f"seed {seeds[0]}"


def verdict_sentences(
    comparison: dict[str, dict[str, bool]],
    seeds: list[int],
    ours: str = "semattnet",
    ours_seeds: list[int] | None = None,
) -> list[str]:
    """One plain sentence per compared method: where ``ours`` (its mean over ``ours_seeds``, by default
    the live ``seeds``) is better and where it is not."""
    live, mine = _mean_of(seeds), _mean_of(ours_seeds or seeds)
    who = f"SemAttNet reference checkpoints (shipped, {mine})" if ours == REFERENCE_KEY else f"SemAttNet ({live})"
    out = []
    for other, wins in comparison.items():
        vs = LABELS[other] + (f" ({live})" if ours == REFERENCE_KEY and other == "two_branch" else "")
        better = [_NAMES[k] for k in DEMO_METRICS if wins[k]]
        worse = [_NAMES[k] for k in DEMO_METRICS if not wins[k]]
        text = f"{who} vs {vs}: "
        text += f"better on {', '.join(better)}" if better else "better on no metric"
        out.append(text + (f"; not better on {', '.join(worse)}." if worse else "."))
    return out


def record(groups: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """group -> results.json metric names (leaderboard units) of
    :meth:`~semattnet.evaluation.metrics.KittiMetrics.compute`'s output."""
    return {g: {k: v[src] for k, src in _RESULT_KEYS.items() if src in v} for g, v in groups.items()}


def machine() -> Machine:
    """CPU model (from /proc/cpuinfo where there is one), core count, torch and Python versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith(("model name", "hardware")):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return Machine(
        cpu=cpu,
        cores=os.cpu_count(),
        torch=torch.__version__,
        python=platform.python_version(),
        platform=platform.platform(),
    )


def write_results(
    path: Path,
    runs: Runs,
    metrics: dict[str, dict[str, dict[str, float]]],
    trained: Trained,
    setup: DemoSetup,
) -> Path:
    """Write ``results.json`` (schema in :mod:`semattnet.apps.demo`)."""
    methods = {
        m: {
            "label": LABELS[m],
            **record(metrics[m]),
            "per_seed": {str(seed): record(run) for seed, run in runs[m].items()},
        }
        for m in metrics
    }
    comparisons_doc = {"semattnet_better_than": setup["comparisons"], "verdicts": setup["verdicts"]}
    if "reference" in setup:
        comparisons_doc["reference_better_than"] = setup["reference"]["comparisons"]
    doc = {
        "schema": RESULTS_SCHEMA,
        "units": {"rmse": "mm", "mae": "mm", "irmse": "1/km", "imae": "1/km"},
        "seeds": setup["seeds"],
        "methods": methods,
        "steps": trained.steps,
        "wall_seconds": {"total": setup["seconds"], "models": {k: round(v, 1) for k, v in trained.seconds.items()}},
        "machine": {**machine(), "device": setup["device"], "torch_threads": setup["torch_threads"]},
        "held_out": setup["held_out"],
        "settings": setup["settings"],
        "recipe": setup["recipe"],
        "comparisons": comparisons_doc,
    }
    if "reference" in setup:
        doc["reference"] = {k: v for k, v in setup["reference"].items() if k != "comparisons"}
    if "uncertainty" in setup:
        doc["uncertainty"] = setup["uncertainty"]
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return path
