"""``semattnet ablate``: paired protocol, per-image results, claims, resume, CLI (tiny budgets)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np
import pytest
from click.testing import CliRunner

import semattnet.apps.ablate as ablate_mod
from semattnet._errors import DataError, InputError
from semattnet.apps.ablate import ABLATION_SCHEMA, CLAIM_CONFIGS, CLAIMS, AblationSettings, run_ablation
from semattnet.cli import main

TINY = {"size": (32, 64), "train_frames": 6, "eval_frames": 4, "backbone_steps": 2, "full_steps": 2, "device": "cpu"}
CLI_TINY = [
    "--size",
    "32x64",
    "--frames",
    "6",
    "--eval-frames",
    "4",
    "--backbone-steps",
    "2",
    "--full-steps",
    "2",
    "--device",
    "cpu",
]


@pytest.fixture(scope="module")
def ablated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any], list[str]]:
    out = tmp_path_factory.mktemp("ablation")
    messages: list[str] = []
    settings = AblationSettings(**TINY, configs=("table2_b", "table2_d"), seeds=(0, 1))
    return out, run_ablation(out, settings, log=messages.append), messages


def test_ablation_json_has_claims(ablated: tuple[Path, dict[str, Any], list[str]]) -> None:
    out, result, messages = ablated
    assert json.loads((out / "ablation.json").read_text()) == json.loads(json.dumps(result))
    assert result["schema"] == ABLATION_SCHEMA and set(result["configs"]) == {"table2_b", "table2_d"}
    assert any(m.startswith("warning: only 2 seeds") for m in messages)
    row = result["configs"]["table2_d"]
    assert row["seeds"] == [0, 1] and row["all"]["mean"] > 0 and row["mae_mm"]["all"]["mean"] > 0
    claims = {c["id"]: c for c in result["claims"]}
    assert list(claims) == [c[0] for c in CLAIMS]
    sem = claims["semantic_branch"]
    assert sem["better"] == "table2_d" and sem["worse"] == "table2_b"
    assert sem["verdict"] in {"supported", "contradicted", "not separated"}
    assert sem["n_pairs"] == 8 and sem["n_seeds"] == 2 and set(sem["per_seed"]) == {"0", "1"}
    assert sem["ci95"][0] <= sem["mean_diff_mm"] <= sem["ci95"][1] and 0 < sem["p"] <= 1
    assert sem["test_units"] == "seed-image pairs" and "mean_diff" in sem["mae"]
    # The claim's mean difference is the difference of the two configurations' mean RMSE (same images).
    gap = result["configs"]["table2_b"]["all"]["mean"] - row["all"]["mean"]
    assert sem["mean_diff_mm"] == pytest.approx(gap)
    for cid in ("refinement", "sammafb", "semantic_input"):
        assert claims[cid]["verdict"] == "skipped" and "not run" in claims[cid]["note"]
    md = (out / "ablation.md").read_text()
    assert "| the semantic branch helps | table2_d vs table2_b |" in md and "skipped: table2_e not run" in md


def test_results_keep_per_image_metrics(ablated: tuple[Path, dict[str, Any], list[str]]) -> None:
    out, _, _ = ablated
    record = json.loads((out / "results" / "table2_b_seed1.json").read_text())
    assert len(record["per_image"]) == 4
    for values in record["per_image"].values():
        assert set(values) == {"rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"}
    mean = np.mean([v["rmse_mm"] for v in record["per_image"].values()])
    assert mean == pytest.approx(record["rmse_mm"]["all"])  # the KITTI score is the mean over images
    assert record["protocol"]["eval_frames"] == 4 and "seeds" not in record["protocol"]


@pytest.mark.slow  # a second ablation run; tests/cli/test_apps_cli.py resumes one through the CLI by default
def test_resume_does_not_retrain(
    ablated: tuple[Path, dict[str, Any], list[str]],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    out, first, _ = ablated
    calls: list[Any] = []
    monkeypatch.setattr(ablate_mod, "train_variant", lambda *a, **k: calls.append(a))
    stamp = (out / "results" / "table2_d_seed0.json").stat().st_mtime_ns
    again = run_ablation(out, AblationSettings(**TINY, configs=("table2_b", "table2_d"), seeds=(0, 1)), log=print)
    assert calls == [] and (out / "results" / "table2_d_seed0.json").stat().st_mtime_ns == stamp
    assert again["claims"] == first["claims"]  # deterministic statistics


def test_refuses_unusable_results(ablated: tuple[Path, dict[str, Any], list[str]], tmp_path: Path) -> None:
    out, _, _ = ablated
    with pytest.raises(DataError, match=r"other settings \(lr\)"):
        run_ablation(out, AblationSettings(**TINY, configs=("table2_b",), seeds=(0,), lr=1e-3), log=print)
    with pytest.raises(
        DataError,
        match="6 training and 4 held-out realistic scenes of \\(32, 64\\) from data seed 0, not 6 and 6 realistic",
    ):
        run_ablation(out, AblationSettings(**{**TINY, "eval_frames": 6}, configs=("table2_b",), seeds=(0,)))
    with pytest.raises(DataError, match="held-out realistic scenes .* not 6 and 4 ideal ones"):
        run_ablation(out, AblationSettings(**{**TINY, "style": "ideal"}, configs=("table2_b",), seeds=(0,)))
    old = tmp_path / "old"
    (old / "results").mkdir(parents=True)
    (old / "data").symlink_to(out / "data")
    (old / "results" / "table2_b_seed0.json").write_text(json.dumps({"rmse_mm": {"all": 1.0}}))
    with pytest.raises(DataError, match="older semattnet ablate without per-image metrics"):
        run_ablation(old, AblationSettings(**TINY, configs=("table2_b",), seeds=(0,)), log=print)


def test_seed_rules(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"paired tests \(semantic_branch\) need at least 2 seeds, got 1"):
        run_ablation(tmp_path, AblationSettings(**TINY, configs=("table2_b", "table2_d"), seeds=(0,)))
    with pytest.raises(InputError, match="distinct"):
        run_ablation(tmp_path, AblationSettings(**TINY, configs=("table2_b",), seeds=(0, 0)))
    assert not any(tmp_path.iterdir())  # refused before any work


@pytest.mark.slow  # ~15 s of training through the CLI; test_ablation_json_has_claims checks the claims by default
def test_cli_claims_shortcut(ablated: tuple[Path, dict[str, Any], list[str]]) -> None:
    out, _, _ = ablated
    stamp = (out / "results" / "table2_b_seed0.json").stat().st_mtime_ns
    result = CliRunner().invoke(main, ["ablate", "--out", str(out), "--configs", "claims", "--seeds", "0,1", *CLI_TINY])
    assert result.exit_code == 0, result.output
    assert (out / "results" / "table2_b_seed0.json").stat().st_mtime_ns == stamp  # reused, not retrained
    summary = json.loads((out / "ablation.json").read_text())
    assert tuple(summary["configs"]) == CLAIM_CONFIGS
    assert all(c["verdict"] != "skipped" for c in summary["claims"])
    assert "| SAMMAFB fusion helps | table2_g vs table2_e |" in result.output
    one = CliRunner().invoke(main, ["ablate", "--out", str(out), "--configs", "claims", "--seeds", "0", *CLI_TINY])
    assert one.exit_code == 1 and one.output.startswith("Error: ") and "at least 2 seeds" in one.output


def test_cli_defaults_match_settings() -> None:
    command = main.commands["ablate"]
    assert isinstance(command, click.Command)
    defaults = {p.name: p.default for p in command.params}
    s = AblationSettings()
    assert defaults["backbone_steps"] == s.backbone_steps and defaults["full_steps"] == s.full_steps
    assert defaults["eval_frames"] == s.eval_frames and defaults["frames"] == s.train_frames
    assert defaults["seeds"] == ",".join(map(str, s.seeds)) and defaults["width"] == s.width
    assert defaults["size"] == f"{s.size[0]}x{s.size[1]}"
