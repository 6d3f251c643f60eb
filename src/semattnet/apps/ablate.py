"""The paper's Table 2 ablations on synthetic scenes (``semattnet ablate``), with paired tests.

Every configuration (a)-(g) of Table 2 is trained from scratch with the same budget of optimiser
steps and several seeds on one synthetic data set, then scored on held-out scenes, separately
for scenes with and without a hard shadow band. One extra row, ``g_unknown_semantics``, trains
and tests (g) with the no-segmenter fallback map, to measure what real semantic maps are worth.

**Paired protocol.** The data (training and held-out scenes) are generated once, from
``data_seed``, and shared by every configuration and seed. For a training seed ``s`` every
configuration gets ``TrainConfig.seed = s``, which fixes the shuffled batch order (a function
of (s, epoch)), the augmentation draws (of (s, epoch, index)) and the global torch / numpy /
random seeds set just before the model is built (so its initialisation). Two configurations
trained with seed ``s`` therefore see the same batches in the same order; their weights start
from the same random stream, identical only as far as their architectures agree. (The full-model
stage of a refining configuration starts its data order again, so its last ``full_steps``
batches repeat the first ones where a non-refining configuration's continue.) Nothing is
validated during training: the held-out scenes are only used for the final scores.

**Claims** (:data:`CLAIMS`): each compares a "better" and a "worse" configuration on the
per-(seed, held-out image) RMSE differences with :func:`semattnet.evaluation.paired.compare`
(mean difference, crossed seed x image bootstrap interval, sign-flip permutation p-value,
verdict), MAE reported alongside.

Results are kept per (configuration, seed) in ``results/``, with every held-out image's metrics,
so an interrupted run continues where it stopped; ``ablation.md`` and ``ablation.json``
summarise them.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._errors import DataError, InputError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.device import resolve_device
from semattnet.apps.experiment import (
    GROUPS,
    HeldOut,
    VariantRecipe,
    complete_held_out,
    fallback_semantic,
    load_held_out,
    make_synthetic,
    score_held_out,
    train_variant,
)
from semattnet.evaluation.metrics import LEADERBOARD, KittiMetrics
from semattnet.evaluation.paired import compare, differences
from semattnet.models.registry import MODELS, TABLE2
from semattnet.segmentation.segmenter import Segmenter, segment_folder

__all__ = ["ABLATION_SCHEMA", "CLAIMS", "CLAIM_CONFIGS", "CONFIGS", "AblationSettings", "run_ablation"]

NO_SEMANTICS = "g_unknown_semantics"
#: Configurations: Table 2 rows plus the no-semantics variant of (g).
CONFIGS: tuple[str, ...] = (*TABLE2, NO_SEMANTICS)
#: The claims tested: (id, text, better configuration, worse configuration).
CLAIMS: tuple[tuple[str, str, str, str], ...] = (
    ("semantic_branch", "the semantic branch helps", "table2_d", "table2_b"),
    ("refinement", "CSPN++ refinement helps", "table2_e", "table2_d"),
    ("sammafb", "SAMMAFB fusion helps", "table2_g", "table2_e"),
    ("semantic_input", "real semantic maps matter (vs the fallback map)", "table2_g", NO_SEMANTICS),
)
#: The configurations the claims need (``--configs claims``).
CLAIM_CONFIGS: tuple[str, ...] = ("table2_b", "table2_d", "table2_e", "table2_g", NO_SEMANTICS)
#: Schema of ``ablation.json``.
ABLATION_SCHEMA = "semattnet.ablation/2"
_RESULT_SCHEMA = 2  # of results/NAME_seedS.json: per-image metrics and the protocol that made them


@dataclass(frozen=True)
class AblationSettings:
    """Common budget: ``backbone_steps + full_steps`` optimiser steps for every configuration
    (refining ones: backbone stage then full model; the others: all in the backbone stage).

    ``style`` is the synthetic scene style (:data:`semattnet.synthetic.SCENE_STYLES`; the
    default ``"realistic"`` has the sensor failures and misleading colour edges where semantics
    carry information); ``extra`` holds further ``TrainConfig`` options for every training run
    (e.g. ``{"amp": True}``).
    """

    size: tuple[int, int] = (96, 320)
    train_frames: int = 200
    eval_frames: int = 48
    width: float = 0.125
    batch_size: int = 2
    lr: float = 2e-3
    backbone_steps: int = 400
    full_steps: int = 150
    seeds: tuple[int, ...] = (0, 1, 2)
    configs: tuple[str, ...] = CONFIGS
    data_seed: int = 0
    style: str = "realistic"
    device: str = "auto"
    extra: dict[str, Any] = field(default_factory=dict)

    def protocol(self) -> dict[str, Any]:
        """The settings a (configuration, seed) result depends on (all but seeds, configs, device)."""
        d = asdict(self)
        return {
            k: list(v) if isinstance(v, tuple) else v for k, v in d.items() if k not in ("seeds", "configs", "device")
        }


def _variant(name: str) -> tuple[str, dict[str, Any]]:
    """Description and model options of a configuration."""
    if name == NO_SEMANTICS:
        return "(g) trained and tested with the no-segmenter fallback map", {
            "branches": 3,
            "fusion": "sammafb",
            "refine": True,
        }
    if name not in MODELS or not name.startswith("table2_"):
        raise InputError(f"unknown configuration {name!r}; choose from {', '.join(CONFIGS)}")
    description, cfg = MODELS[name].description, MODELS[name].config
    return description, {"branches": cfg.branches, "fusion": cfg.fusion, "refine": cfg.refine}


def _stats(values: list[float]) -> dict[str, float]:
    a = np.asarray(values, dtype=np.float64)
    return {"mean": float(a.mean()), "std": float(a.std(ddof=1)) if len(a) > 1 else 0.0}


def _check_seeds(s: AblationSettings, log: Callable[[str], None]) -> None:
    """Refuse fewer than 2 distinct seeds when a claim can be tested; warn below 3."""
    if len(set(s.seeds)) != len(s.seeds) or not s.seeds:
        raise InputError(f"seeds must be distinct and at least one, got {list(s.seeds)}")
    testable = [c[0] for c in CLAIMS if {c[2], c[3]} <= set(s.configs)]
    if testable and len(s.seeds) < 2:
        raise InputError(f"the paired tests ({', '.join(testable)}) need at least 2 seeds, got {len(s.seeds)}")
    if testable and len(s.seeds) < 3:
        log(f"warning: only {len(s.seeds)} seeds; the paired tests are weak below 3")


def run_ablation(
    out_dir: str | Path, settings: AblationSettings | None = None, log: Callable[[str], None] = print
) -> dict[str, Any]:
    """Train and score every configuration and seed, test the claims; returns (and writes) the summary."""
    s = settings or AblationSettings()
    for name in s.configs:
        _variant(name)  # fail early on a typo
    _check_seeds(s, log)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(s.device)
    run = _Run(out, s, _held_out(out / "data", s, log), device, log)
    results = {name: {seed: run.result(name, seed) for seed in s.seeds} for name in s.configs}
    summary = {name: _summary(name, runs) for name, runs in results.items()}
    claims = _claims(results, s.seeds)
    result = {
        "schema": ABLATION_SCHEMA,
        "settings": asdict(s),
        "device": str(device),
        "units": {"rmse": "mm", "mae": "mm"},
        "configs": summary,
        "claims": claims,
    }
    (out / "ablation.json").write_text(json.dumps(result, indent=2) + "\n")
    (out / "ablation.md").write_text(_markdown(summary, claims, s))
    log(f"wrote {out / 'ablation.md'}")
    return result


def _held_out(data: Path, s: AblationSettings, log: Callable[[str], None]) -> HeldOut:
    """The held-out scenes: of a previous run's data if there is one (to continue it), else of new data."""
    if (data / "scenes.json").is_file():
        manifest = json.loads((data / "scenes.json").read_text())
        counts = manifest.get("counts", {})
        found = (
            counts.get("train"),
            counts.get("val_select"),
            tuple(manifest.get("size", ())),
            manifest.get("seed"),
            manifest.get("style", "ideal"),
        )
        wanted = (s.train_frames, s.eval_frames, tuple(s.size), s.data_seed, s.style)
        if found != wanted:
            msg = (
                f"{data} holds {found[0]} training and {found[1]} held-out {found[4]} scenes of {found[2]} from "
                f"data seed {found[3]}, not {wanted[0]} and {wanted[1]} {wanted[4]} ones of {wanted[2]} from seed "
                f"{wanted[3]}; use another --out for other data settings"
            )
            raise DataError(msg)
        return load_held_out(data)
    log(f"generating {s.train_frames} training and {s.eval_frames} held-out scenes at {s.size[0]}x{s.size[1]} ...")
    return make_synthetic(data, s.train_frames, s.eval_frames, s.size, s.data_seed, style=s.style)


def _per_image(preds: Mapping[str, np.ndarray], held: HeldOut) -> dict[str, dict[str, float]]:
    """Every held-out image's KITTI metrics in leaderboard units (``rmse_mm``, ``mae_mm``, ``irmse_per_km`` ...)."""
    m = KittiMetrics(keep_per_image=True)
    for n, pred in preds.items():
        m.update(torch.from_numpy(pred)[None, None], torch.from_numpy(held.gts[n])[None, None], names=[n])
    keys = {k: (f"{k}_{'mm' if unit == 'mm' else 'per_km'}", scale) for k, (_, unit, scale) in LEADERBOARD.items()}
    return {str(row["name"]): {key: float(row[k]) * scale for k, (key, scale) in keys.items()} for row in m.per_image}


@dataclass(frozen=True)
class _Run:
    """One ablation run: where it writes, its settings, the held-out scenes, the device, where progress goes."""

    out: Path
    settings: AblationSettings
    held: HeldOut
    device: torch.device
    log: Callable[[str], None]

    def result(self, name: str, seed: int) -> dict[str, Any]:
        """One (configuration, seed): saved by an earlier run, or trained, scored and saved.

        Keys: ``rmse_mm`` and ``mae_mm`` per group, ``metrics`` (all KITTI metrics per group),
        ``per_image`` (held-out scene -> its metrics), ``protocol``, ``seconds``.
        """
        path = self.out / "results" / f"{name}_seed{seed}.json"
        if path.is_file():
            return self._load(path)
        self.log(f"{name} ({_variant(name)[0]}), seed {seed} ...")
        t0 = time.perf_counter()
        metrics, per_image = self.train_and_score(name, seed)
        record: dict[str, Any] = {
            "schema": _RESULT_SCHEMA,
            "protocol": self.settings.protocol(),
            **{k: {g: metrics[g][k] for g in GROUPS} for k in ("rmse_mm", "mae_mm")},
            "metrics": metrics,
            "per_image": per_image,
            "seconds": time.perf_counter() - t0,
        }
        with atomic_path(path, suffix=".json") as tmp:
            tmp.write_text(json.dumps(record, indent=1))
        rmse = record["rmse_mm"]
        self.log(f"  RMSE {rmse['all']:.0f} mm (shadowed {rmse['shadowed']:.0f}, unshadowed {rmse['unshadowed']:.0f})")
        return record

    def _load(self, path: Path) -> dict[str, Any]:
        """A saved result, refused if it lacks per-image metrics or was made with other settings."""
        record = json.loads(path.read_text())
        if record.get("schema") != _RESULT_SCHEMA or "per_image" not in record:
            raise DataError(
                f"{path} was written by an older semattnet ablate without per-image metrics, which "
                "the paired tests need; move results/ away or use another --out"
            )
        expected = json.loads(json.dumps(self.settings.protocol()))
        changed = sorted(
            k for k in expected.keys() | record["protocol"].keys() if expected.get(k) != record["protocol"].get(k)
        )
        if changed:
            raise DataError(
                f"{path} was made with other settings ({', '.join(changed)}); "
                "rerun with the same settings or use another --out"
            )
        return record

    def train_and_score(self, name: str, seed: int) -> tuple[dict[str, dict[str, float]], dict[str, dict[str, float]]]:
        """Train a configuration from scratch with the common step budget; KITTI metrics on the held-out
        scenes per group, and per image."""
        s, data, (_, opts) = self.settings, self.out / "data", _variant(name)
        extra: dict[str, Any] = {**s.extra, "val_split": ""}  # the held-out scenes are for the final scores only
        semantic = None
        if name == NO_SEMANTICS:  # trained on fallback maps written beside the real ones, tested on them too
            blank_root = data / "semantic_unknown"
            segment_folder(Segmenter(None, "unknown"), data / "kitti_raw", blank_root, progress=False)
            extra["semantic_root"], semantic = str(blank_root), fallback_semantic
        refine = opts["refine"]
        steps = s.backbone_steps if refine else s.backbone_steps + s.full_steps
        recipe = VariantRecipe(
            steps,
            s.full_steps,
            s.size,
            s.width,
            s.batch_size,
            s.lr,
            seed,
            refine=refine,
            fields={"branches": opts["branches"], "fusion": opts["fusion"], **extra},
        )
        ckpt = train_variant(self.out / "runs" / name / f"seed{seed}", data, recipe, self.device, log=lambda _m: None)
        outputs = complete_held_out(ckpt, self.held, self.device, semantic=semantic)
        key = "refined_depth" if refine else "fused_depth"
        preds = {n: o[key] for n, o in outputs.items()}
        return score_held_out(preds, self.held), _per_image(preds, self.held)


def _summary(name: str, runs: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """One configuration: description, seeds, RMSE mean and std per group (``all``, ``shadowed``,
    ``unshadowed``) and every seed's, and the same for MAE under ``mae_mm``."""
    seeds = sorted(runs)

    def block(metric: str) -> dict[str, Any]:
        return {
            **{g: _stats([runs[sd][metric][g] for sd in seeds]) for g in GROUPS},
            "per_seed": {str(sd): runs[sd][metric] for sd in seeds},
        }

    return {"description": _variant(name)[0], "seeds": seeds, **block("rmse_mm"), "mae_mm": block("mae_mm")}


def _claims(results: dict[str, dict[int, dict[str, Any]]], seeds: tuple[int, ...]) -> list[dict[str, Any]]:
    """Every claim of :data:`CLAIMS`: the paired test on per-image RMSE (verdict) and MAE, or skipped."""
    out = []
    for cid, text, better, worse in CLAIMS:
        row: dict[str, Any] = {"id": cid, "claim": text, "better": better, "worse": worse}
        missing = [c for c in (better, worse) if c not in results]
        if missing:
            out.append({**row, "verdict": "skipped", "note": f"{' and '.join(missing)} not run"})
            continue
        tests = {}
        for metric in ("rmse_mm", "mae_mm"):
            per_image = {
                c: {sd: {n: v[metric] for n, v in results[c][sd]["per_image"].items()} for sd in seeds}
                for c in (better, worse)
            }
            d, common, _ = differences(per_image[worse], per_image[better])
            tests[metric] = compare(d, common)
        r = tests["rmse_mm"]
        out.append(
            {
                **row,
                "verdict": r["verdict"],
                "mean_diff_mm": r["mean_diff"],
                "ci95": r["ci95"],
                "p": r["p"],
                "test_units": r["test_units"],
                "per_seed": r["per_seed"],
                "seeds_agreeing": r["seeds_agreeing"],
                "n_seeds": r["n_seeds"],
                "n_pairs": r["n_pairs"],
                "mae": tests["mae_mm"],
            }
        )
    return out


def _cell(v: dict[str, float]) -> str:
    return f"{v['mean']:.0f} ± {v['std']:.0f}"


def _markdown(summary: dict[str, Any], claims: list[dict[str, Any]], s: AblationSettings) -> str:
    """``ablation.md``: the configurations table, then the claims table."""
    lines = [
        f"Synthetic {s.size[0]}x{s.size[1]} scenes ({s.train_frames} training, {s.eval_frames} held out, half with a "
        f"shadow band), width {s.width}, {s.backbone_steps} + {s.full_steps} steps of batch {s.batch_size}, "
        f"seeds {', '.join(map(str, s.seeds))} (paired). RMSE and MAE in mm, mean ± standard deviation over seeds.",
        "",
        "| Config | Model | RMSE | shadowed | unshadowed | MAE | RMSE per seed |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    for name, row in summary.items():
        seeds = ", ".join(f"{row['per_seed'][str(sd)]['all']:.0f}" for sd in row["seeds"])
        lines.append(
            f"| {name} | {row['description']} | {_cell(row['all'])} | {_cell(row['shadowed'])} | "
            f"{_cell(row['unshadowed'])} | {_cell(row['mae_mm']['all'])} | {seeds} |"
        )
    lines += [
        "",
        "Claims: d = RMSE(worse) - RMSE(better) per (seed, held-out image); > 0 favours the claim. "
        "95 % CI: crossed seed x image bootstrap; p: two-sided sign-flip test. Supported: CI above 0 and "
        "p < 0.05; contradicted: CI below 0 and p < 0.05; otherwise not separated.",
        "",
        "| Claim | better vs worse | ΔRMSE [mm] (95 % CI) | p | seeds agreeing | per-seed ΔRMSE | ΔMAE [mm] "
        "(95 % CI) | verdict |",
        "|---|---|---:|---:|---:|---|---:|---|",
    ]
    lines += [_claim_row(c) for c in claims]
    return "\n".join(lines) + "\n"


def _claim_row(c: dict[str, Any]) -> str:
    """One row of the claims table."""
    pair = f"{c['better']} vs {c['worse']}"
    if c["verdict"] == "skipped":
        return f"| {c['claim']} | {pair} | | | | | | skipped: {c['note']} |"
    m, per_seed = c["mae"], ", ".join(f"{v:+.0f}" for v in c["per_seed"].values())
    return (
        f"| {c['claim']} | {pair} | {c['mean_diff_mm']:+.0f} ({c['ci95'][0]:+.0f}, {c['ci95'][1]:+.0f}) | "
        f"{c['p']:.3g} | {c['seeds_agreeing']}/{c['n_seeds']} | {per_seed} | "
        f"{m['mean_diff']:+.0f} ({m['ci95'][0]:+.0f}, {m['ci95'][1]:+.0f}) | **{c['verdict']}** |"
    )
