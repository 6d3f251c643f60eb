"""benchmarks/shift.py: the acceptance summary, the table, the docs markers, the call of `semattnet adapt`, its
refusals, and (slow) the whole benchmark at a toy size."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import ModuleType
from typing import Any

import click
import pytest
import torch

from semattnet._errors import InputError
from semattnet.cli import main as cli
from tests.benchmarks._scripts import load_script

LOSS_ALL = "sparse,photometric,smoothness"


@pytest.fixture(scope="module")
def shift() -> ModuleType:
    return load_script("shift")


def _row(rmse: float, mae: float = 1000.0, irmse: float = 5.0, imae: float = 3.0) -> dict[str, Any]:
    scores = {"rmse_mm": rmse, "mae_mm": mae, "irmse_per_km": irmse, "imae_per_km": imae}
    return {"per_seed": {"0": scores, "1": scores}, "scores": scores}


def _results(**rows: dict[str, Any]) -> dict[str, Any]:
    settings = {"seeds": [0, 1], "adapt_steps": 800, "ablation_steps": 400}
    return {
        "command": "python benchmarks/shift.py --tiny",
        "settings": settings,
        "device": "cpu",
        "machine": "a CPU",
        "seconds": {"total": 60.0},
        "rows": rows,
    }


def test_summary_is_the_share_of_the_gap_closed_and_the_classical_comparison(shift: ModuleType) -> None:
    rows = {
        "classical": _row(3000, 900, 9, 4),
        "unadapted": _row(8000),
        "adapted_all": _row(4000, 800, 4, 2),
        "supervised": _row(2000),
    }
    assert shift.summary(rows) == {
        "gap_closed": pytest.approx(4000 / 6000),
        "beats_classical": False,
        "accepted": False,
    }
    rows["adapted_all"] = _row(2900, 800, 4, 2)
    assert shift.summary(rows)["beats_classical"] and shift.summary(rows)["accepted"]
    rows["adapted_all"] = _row(2900, 901, 4, 2)  # worse than classical on MAE alone
    assert not shift.summary(rows)["beats_classical"]
    assert shift.summary({k: v for k, v in rows.items() if k != "adapted_all"}) == {}


def test_table_and_docs_between_the_markers(shift: ModuleType, tmp_path: Path) -> None:
    rows = {
        "classical": _row(3000, 2000, 9, 4),
        "unadapted": _row(8000),
        "adapted_all": _row(2500),
        "adapted_sparse": _row(2700),
        "supervised": _row(2000),
    }
    results = _results(**rows) | {"summary": shift.summary(rows)}
    text = shift.table(results)
    assert "| adapted: all three losses, 800 steps (the recipe) | 2500 | 1000 | 5.00 | 3.00 | 2500, 2500 |" in text
    assert "| adapted: sparse, 400 steps | 2700 |" in text
    assert text.index("adapted: sparse") < text.index("adapted: all") < text.index("supervised")
    assert "(all three losses, 800 steps) closes **92 %** of the RMSE gap" in text and "beats the classical" in text
    page = tmp_path / "docs" / "guides" / "page.md"
    page.parent.mkdir(parents=True)
    page.write_text(f"# Page\n\nbefore\n\n{shift.MARKERS[0]}\nold table\n{shift.MARKERS[1]}\n\nafter\n")
    shift.update_docs(page, results, tmp_path / "docs" / "shift.png")
    new = page.read_text()
    assert "old table" not in new and "before" in new and "after" in new and "](../shift.png)" in new
    assert new.count(shift.MARKERS[0]) == 1 and "| classical completion | 3000 |" in new
    page.write_text("# no markers\n")
    with pytest.raises(InputError, match="needs one <!-- shift-results:start --> line"):
        shift.update_docs(page, results, tmp_path / "shift.png")
    shipped = shift.DOC_PAGE.read_text()
    assert all(shipped.count(m) == 1 for m in shift.MARKERS) and shift.COMMAND in shipped


def test_adapt_rows_call_semattnet_adapt_per_loss_and_seed(
    shift: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With an `adapt` command in the CLI, every row and seed is adapted once with the documented options (the
    recipe's steps for `all`, the ablation's for the others), the result saved under checkpoints/ and scored; an
    earlier result is read back, not adapted again."""
    calls: list[list[str]] = []

    @click.command("adapt", context_settings={"ignore_unknown_options": True})
    @click.argument("args", nargs=-1, type=click.UNPROCESSED)
    def fake_adapt(args: tuple[str, ...]) -> None:
        calls.append(list(args))
        run = Path(args[args.index("--out") + 1])
        run.mkdir(parents=True)
        (run / "adapted.safetensors").write_bytes(f"weights {len(calls)}".encode())

    monkeypatch.setitem(cli.commands, "adapt", fake_adapt)
    monkeypatch.setattr(shift, "score_model", lambda path, held, s, device: {k: 1.0 for k in shift.METRICS})
    weights = {0: tmp_path / "w0.safetensors", 1: tmp_path / "w1.safetensors"}
    data = {"drive": tmp_path / "drive", "semantic": tmp_path / "sem", "held_target": None}
    s = shift.tiny(seeds=(0, 1))
    rows = shift.adapt_rows(tmp_path, weights, data, s, torch.device("cpu"), shift.Clock(), log=lambda _: None)
    assert list(rows) == [f"adapted_{k}" for k in shift.LOSSES] and len(calls) == 10
    assert calls[1] == [
        "--weights",
        str(weights[1]),
        "--kitti-raw",
        str(tmp_path / "drive"),
        "--out",
        str(tmp_path / "adapt" / "all_seed1"),
        "--steps",
        "2",
        "--loss",
        LOSS_ALL,
        "--seed",
        "1",
        "--lr",
        "0.001",
        "--semantic",
        str(tmp_path / "sem"),
    ]
    assert calls[2][calls[2].index("--out") + 1 :][:3] == [str(tmp_path / "adapt" / "all_short_seed0"), "--steps", "1"]
    assert [c[c.index("--loss") + 1] for c in calls[::2]] == [LOSS_ALL, LOSS_ALL, "sparse", "photometric", "smoothness"]
    assert (tmp_path / "checkpoints" / "adapted_photometric_seed0.safetensors").read_bytes() == b"weights 7"
    assert (
        rows["adapted_all"]["scores"]["rmse_mm"] == 1.0
        and rows["adapted_all"]["loss"] == "sparse,photometric,smoothness"
    )
    shift.adapt_rows(tmp_path, weights, data, s, torch.device("cpu"), shift.Clock(), log=lambda _: None)
    assert len(calls) == 10  # read back
    monkeypatch.delitem(cli.commands, "adapt")
    lines: list[str] = []
    assert shift.adapt_rows(tmp_path, weights, data, s, torch.device("cpu"), shift.Clock(), log=lines.append) == {}
    assert lines == ["[shift] adapted rows skipped: this checkout has no `semattnet adapt` command"]


def test_refusals_are_one_line_errors(shift: ModuleType, tmp_path: Path) -> None:
    (tmp_path / "results.json").write_text("{}")
    with pytest.raises(InputError, match="results.json exists; pass --overwrite"):
        shift.main(["--out", str(tmp_path), "--tiny"])
    with pytest.raises(InputError, match="--seeds must be integers"):
        shift.main(["--out", str(tmp_path / "new"), "--seeds", "a,b"])
    assert not (tmp_path / "new").exists()


@pytest.mark.slow  # generates every tree and trains two toy models through the three stages: ~1 minute on 2 cores
def test_tiny_run(shift: ModuleType, tmp_path: Path) -> None:
    page = tmp_path / "domain-shift.md"
    shutil.copy(shift.DOC_PAGE, page)
    results = shift.main(["--out", str(tmp_path / "run"), "--tiny", "--device", "cpu", "--docs", str(page)])
    saved = json.loads((tmp_path / "run" / "results.json").read_text())
    assert (
        saved["rows"].keys()
        == results["rows"].keys()
        >= {"classical", "unadapted", "supervised", "unadapted_on_source"}
    )
    assert ("adapted_all" in saved["rows"]) == shift.adapt_available()
    assert set(saved["rows"]["unadapted"]["scores"]) == set(shift.METRICS)
    assert {"data", "train_source", "train_supervised", "score", "total"} <= set(saved["seconds"])
    for key in ("source_seed0", "supervised_seed0"):
        assert (tmp_path / "run" / "checkpoints" / f"{key}.safetensors").is_file()
    drive = tmp_path / "run" / "data" / "recording" / "kitti_raw" / "2000_01_01" / "2000_01_01_drive_3000_sync"
    assert len(list((drive / "image_03" / "data").glob("*.png"))) == 2 * 3
    assert "| source model, unadapted |" in page.read_text() and (tmp_path / "domain-shift.png").is_file()
    lines: list[str] = []
    again = shift.run(tmp_path / "run", shift.tiny(), torch.device("cpu"), overwrite=True, log=lines.append)
    assert "[shift] source, seed 0: trained earlier" in lines[0]
    assert again["rows"]["unadapted"] == saved["rows"]["unadapted"]


def test_factor_domains_take_one_group_of_the_target_rig_each(shift: ModuleType) -> None:
    from semattnet.synthetic.domain import SOURCE, TARGET

    domains = shift.factor_domains()
    assert list(domains) == [*shift.FACTORS, "all: the target"] and domains["all: the target"] == TARGET
    lidar = domains["LiDAR"]
    assert (lidar.beams, lidar.lidar_pitch, lidar.camera_pitch, lidar.focal_scale) == (32, 2.0, 0.0, 1.0)
    assert domains["image size"] == shift.dataclasses.replace(SOURCE, name="source+image-size")
    grouped = [f for fields in shift.FACTORS.values() for f in fields]
    differing = [f.name for f in shift.dataclasses.fields(TARGET) if getattr(TARGET, f.name) != getattr(SOURCE, f.name)]
    assert sorted(grouped) == sorted(f for f in differing if f != "name")  # every difference in one group
    rows = {
        "source": {"reference": _row(1500, 600), "classical": _row(4500, 1300)["scores"]},
        "lens": {"reference": _row(6900, 4500), "classical": _row(3800, 985)["scores"]},
    }
    text = shift.gap_table(rows)
    assert "| source | 1500 | 600 | 4500 | 1300 |" in text and "| source rig, the target's lens | 6900 |" in text
    shipped = shift.DOC_PAGE.read_text()
    assert all(shipped.count(m) == 1 for m in shift.GAP_MARKERS)


def test_the_source_models_are_the_shipped_references_when_the_recipe_is_theirs(
    shift: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The full run's source model of a seed is that seed's shipped reference (read, not trained again); any other
    recipe, size or model trains."""
    from semattnet.apps.demo.reference import shipped_references
    from semattnet.weights.checkpoint import load_checkpoint

    trained: list[str] = []
    monkeypatch.setattr(shift, "_train_variant", lambda run, *a, **k: trained.append(run.name) or 1 / 0)
    s = shift.ShiftSettings()
    saved = shift.train_model(tmp_path, "source", tmp_path, s.recipe.size, s, 1, torch.device("cpu"), lambda _: None)
    want, got = load_checkpoint(shipped_references()[1]).state_dict, load_checkpoint(saved).state_dict
    assert trained == [] and want.keys() == got.keys() and all(torch.equal(want[k], got[k]) for k in want)
    for key, size in (("supervised", s.recipe.size), ("source", s.target_size)):
        with pytest.raises(ZeroDivisionError):
            shift.train_model(tmp_path, key, tmp_path, size, s, 0, torch.device("cpu"), lambda _: None)
    assert trained == ["supervised_seed0", "source_seed0"]
