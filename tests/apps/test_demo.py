"""The demo end to end (shortened) and its HTML report rendered by headless Chromium."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from semattnet.apps.demo import DemoSettings, run_demo

SHORT = DemoSettings(size=(64, 192), train_frames=8, eval_frames=4, steps=(3, 2), batch_size=2)


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    out = tmp_path_factory.mktemp("demo")
    lines: list[str] = []
    return run_demo(out, SHORT, overwrite=True, log=lines.append), lines


def test_short_demo_writes_report(demo_run) -> None:  # type: ignore[no-untyped-def]
    result, lines = demo_run
    out = result.out_dir
    assert lines[-1].startswith("done in") and str(result.report_html.resolve()) in lines[-1]
    assert set(result.metrics) == {"sparse", "classical", "semattnet", "two_branch", "reference"}
    for method, groups in result.metrics.items():
        assert set(groups) == {"all", "shadowed", "unshadowed"}, method
        assert groups["all"]["images"] == 4 and groups["shadowed"]["images"] == 2
        assert np.isfinite(groups["all"]["rmse_mm"])
    # The classical completion is far better than the devkit-filled sparse input.
    assert result.metrics["classical"]["all"]["rmse_mm"] < 0.5 * result.metrics["sparse"]["all"]["rmse_mm"]
    assert result.steps == {"semattnet": {"backbone": 3, "full": 2}, "two_branch": {"backbone": 3, "full": 2}}
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["metrics"]["semattnet"]["all"] == pytest.approx(result.metrics["semattnet"]["all"])
    md = result.report_md.read_text()
    assert "| Classical completion |" in md and "RMSE shadowed [mm]" in md
    images = [line.split("](")[1].rstrip(")") for line in md.splitlines() if line.startswith("![")]
    assert len(images) == 9  # 2 comparisons, 2 branch panels, 4 training curves, the sparsification curves
    assert "Uncertainty of Classical completion, AUSE / AURG of RMSE" in md
    unc = json.loads((out / "results.json").read_text())["uncertainty"]
    assert set(unc) == {"classical", "semattnet", "two_branch", "reference"}
    for method, scores in unc.items():
        assert set(scores["per_seed"]) == {"0", "1"}, method
        mean = np.mean([s["ause_rmse"] for s in scores["per_seed"].values()])
        assert scores["ause_rmse"] == pytest.approx(mean) and np.isfinite(scores["aurg_mae"]), method
        assert len(scores["curves"]["rmse_curve"]) == 100 and scores["curves"]["rmse_curve"][0] == pytest.approx(1)
    assert "Reference checkpoints (shipped, demo_reference_seedS.safetensors.gz, one per training seed 0, 1)" in md
    assert "Live recipe" in md
    for rel in images:
        assert (out / rel).is_file(), rel
    for run in ("semattnet", "two_branch"):
        for stage in ("backbone", "full"):
            assert (out / "runs" / run / stage / "checkpoints" / "last.pt").is_file()


def test_demo_refuses_a_non_empty_folder(tmp_path: Path) -> None:
    (tmp_path / "keep.txt").write_text("x")
    with pytest.raises(FileExistsError, match="not empty"):
        run_demo(tmp_path, SHORT)
    assert (tmp_path / "keep.txt").read_text() == "x"


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return shutil.which(name)
    if os.environ.get("SEMATTNET_REQUIRE_BROWSER"):
        pytest.fail("no Chromium found: run scripts/setup-browser.sh")
    pytest.skip("no Chromium (scripts/setup-browser.sh installs it)")
    return None


def _headless(browser: str, *args: str) -> subprocess.CompletedProcess[str]:
    flags = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-extensions",
        "--hide-scrollbars",
    ]
    return subprocess.run([browser, *flags, *args], capture_output=True, text=True, timeout=120, check=True)


@pytest.mark.slow  # a second Chromium start on the demo's report; tests/viz/test_viewer.py renders reports by default
def test_report_renders_in_chromium(demo_run, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    browser = _chromium()
    assert browser is not None
    result, _ = demo_run
    url = result.report_html.resolve().as_uri()
    dom = _headless(browser, "--virtual-time-budget=5000", "--dump-dom", url).stdout
    n = result.report_html.read_text().count("<img ")
    assert n == 9 and f'data-images="{n}/{n}"' in dom, dom[:500]  # every <img> decoded (the page's load handler)
    assert '<p class="broken">' not in dom
    shot = tmp_path / "report.png"
    _headless(browser, "--window-size=1200,2400", f"--screenshot={shot}", url)
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(np.int16)
    assert pixels.shape[:2] == (2400, 1200)
    # Not a blank page: the figures put many distinct colours on screen.
    assert len(np.unique(pixels.reshape(-1, 3)[::7], axis=0)) > 1000


def test_broken_image_is_flagged(tmp_path: Path) -> None:
    browser = _chromium()
    assert browser is not None
    from semattnet.viz.report import write_report

    metrics = {"sparse": {"all": {"rmse_mm": 1.0, "mae_mm": 1.0, "irmse_per_km": 1.0, "imae_per_km": 1.0}}}
    setup = {"held_out": {"frames": 1, "shadowed": 0}, "device": "cpu", "torch_threads": 1, "seconds": 1.0}
    _, html = write_report(tmp_path, metrics, {}, [("gone", "nope.png")], setup)
    dom = _headless(browser, "--virtual-time-budget=5000", "--dump-dom", html.as_uri()).stdout
    assert 'data-images="0/1"' in dom and '<p class="broken">missing image: nope.png</p>' in dom


def test_results_json_schema(demo_run) -> None:  # type: ignore[no-untyped-def]
    result, _ = demo_run
    doc = json.loads(result.results_json.read_text())
    assert result.results_json == result.out_dir / "results.json"
    assert doc["schema"] == "semattnet.demo.results/2" and doc["seeds"] == [0, 1]
    assert doc["units"] == {"rmse": "mm", "mae": "mm", "irmse": "1/km", "imae": "1/km"}
    assert set(doc["methods"]) == {"sparse", "classical", "semattnet", "two_branch", "reference"}
    for method, rec in doc["methods"].items():
        assert isinstance(rec["label"], str)
        assert set(rec["per_seed"]) == {"0", "1"}
        for groups in (rec, rec["per_seed"]["0"], rec["per_seed"]["1"]):
            for group in ("all", "shadowed", "unshadowed"):
                assert set(groups[group]) == {"rmse", "mae", "irmse", "imae", "images"}, (method, group)
                assert all(isinstance(v, (int, float)) for v in groups[group].values())
        assert rec["all"]["rmse"] == pytest.approx(result.metrics[method]["all"]["rmse_mm"])
    assert doc["steps"] == result.steps
    assert set(doc["wall_seconds"]) == {"total", "models"} and set(doc["wall_seconds"]["models"]) == set(result.steps)
    assert {"cpu", "cores", "torch", "python", "device", "torch_threads"} <= set(doc["machine"])
    assert doc["settings"]["size"] == [64, 192] and doc["held_out"] == {"frames": 4, "shadowed": 2}
    assert doc["settings"]["style"] == "realistic"
    # the headline of a learned model is the mean of its seeds
    sem = doc["methods"]["semattnet"]
    assert sem["all"]["rmse"] == pytest.approx(
        (sem["per_seed"]["0"]["all"]["rmse"] + sem["per_seed"]["1"]["all"]["rmse"]) / 2
    )
    wins = doc["comparisons"]["semattnet_better_than"]
    assert set(wins) == {"classical", "two_branch"} and set(wins["classical"]) == {"rmse", "mae", "irmse", "imae"}
    assert wins["classical"]["mae"] == (sem["all"]["mae"] < doc["methods"]["classical"]["all"]["mae"])
    assert len(doc["comparisons"]["verdicts"]) == 4  # SemAttNet and the reference, each against two
    ref, methods = doc["reference"], doc["methods"]
    assert ref["seeds"] == [0, 1] and [f["seed"] for f in ref["files"]] == [0, 1]
    for f in ref["files"]:
        assert f["file"] == f"demo_reference_seed{f['seed']}.safetensors.gz" and f["bytes"] < 5_000_000
        assert len(f["sha256"]) == 64 and set(f["own_validation"]) == {"reference", "classical"}
    assert "--train-reference" in ref["command"] and ref["recipe"]["loss"] == "l1+l2" and "seed" not in ref["recipe"]
    shipped = methods["reference"]  # two checkpoints (training seeds 0, 1): the headline is their mean
    assert shipped["per_seed"]["0"] != shipped["per_seed"]["1"]
    assert shipped["all"]["mae"] == pytest.approx(
        (shipped["per_seed"]["0"]["all"]["mae"] + shipped["per_seed"]["1"]["all"]["mae"]) / 2
    )
    assert methods["classical"]["per_seed"]["0"] == methods["classical"]["per_seed"]["1"]  # not trained
    assert doc["comparisons"]["reference_better_than"]["classical"]["rmse"] == (
        methods["reference"]["all"]["rmse"] < methods["classical"]["all"]["rmse"]
    )
    assert doc["recipe"]["live"] and doc["recipe"]["reference"]


def test_report_shows_every_seed_and_the_verdicts(demo_run) -> None:  # type: ignore[no-untyped-def]
    result, _ = demo_run
    md = result.report_md.read_text()
    assert "| SemAttNet (CG + SG + DG, SAMMAFB, CSPN++), mean of 2 seeds |" in md
    for seed in (0, 1):
        assert f"|   SemAttNet, seed {seed} |" in md and f"|   Two-branch ablation, seed {seed} |" in md
    assert "SemAttNet (mean of seeds 0, 1) vs Classical completion: better on" in md
    assert (
        "SemAttNet reference checkpoints (shipped, mean of seeds 0, 1) vs Two-branch ablation (CG + DG, SAMMAFB, "
        "CSPN++) (mean of seeds 0, 1): better on" in md
    )
    assert (
        "| SemAttNet reference checkpoints (shipped, trained once for longer; not trained by this run), "
        "mean of 2 seeds |" in md
    )
    assert "|   SemAttNet reference checkpoints, seed 1 |" in md


@pytest.mark.slow  # as above, on the demo's viewer
def test_demo_viewer_in_chromium(demo_run) -> None:  # type: ignore[no-untyped-def]
    from semattnet.data.io import read_depth
    from tests.apps._browser import hover_pixel, open_page, wait_ready

    result, _ = demo_run
    out = result.out_dir
    assert result.viewer_html == out / "viewer.html" and 'href="viewer.html"' in result.report_html.read_text()
    size = sum(p.stat().st_size for p in [out / "viewer.html", out / "plotly.min.js", *(out / "viewer").iterdir()])
    assert size < 15e6
    name = json.loads((out / "viewer" / "000.js").read_text().split(",", 1)[1].rstrip(");\n"))["name"]
    gt = read_depth(
        next(out.glob(f"data/**/groundtruth_depth/{name.replace('_image_', '_groundtruth_depth_', 1)}.png"))
    )
    v, u = np.argwhere(gt > 0)[len(np.argwhere(gt > 0)) // 3]
    with open_page(result.viewer_html) as (page, errors):
        wait_ready(page)
        values = hover_pixel(page, int(u), int(v))
        assert values["gt"] == pytest.approx(gt[v, u], abs=0.01)
        assert {
            "lidar",
            "depth_semattnet",
            "depth_two_branch",
            "depth_classical",
            "depth_reference",
            "out_color_conf",
        } <= set(values)
        layers = page.eval_on_selector_all("#layers input", "xs => xs.map((x) => x.value)")
        assert {"rgb", "semantic", "out_color_depth", "out_fused_depth", "error_semattnet"} <= set(layers)
        counts = page.evaluate("document.getElementById('cloud').data.map((t) => t.x.length)")
        assert counts[0] > 0 and counts[1] > 0
    assert errors == []


def test_step_plan_equal_steps_or_equal_time(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Equal steps (the paper's protocol): both models get the same counts, filling the budget together;
    equal time: each model gets half the budget, so the cheaper one takes more steps."""
    from semattnet.apps.demo import recipe as demo

    times = {3: (0.25, 0.5), 2: (0.125, 0.25)}  # seconds per (backbone, full) step: three- and two-branch
    monkeypatch.setattr(demo, "step_times", lambda s, device, overrides: times[overrides["branches"]])
    monkeypatch.setattr(demo, "OVERHEAD", 1.0)
    s = demo.DemoSettings(minutes=1.0, backbone_share=0.5, seeds=(0,), steps=None)
    plan = demo.step_plan(s, torch.device("cpu"))
    assert plan["semattnet"] == plan["two_branch"] == (80, 40)  # 30 s / (0.25 + 0.125), 30 s / (0.5 + 0.25)
    spent = sum(
        n_bb * times[b][0] + n_full * times[b][1] for (n_bb, n_full), b in zip(plan.values(), (3, 2), strict=True)
    )
    assert spent == pytest.approx(60.0)
    plan = demo.step_plan(
        demo.DemoSettings(minutes=1.0, backbone_share=0.5, equal_steps=False, seeds=(0,), steps=None),
        torch.device("cpu"),
    )
    assert plan == {"semattnet": (60, 30), "two_branch": (120, 60)}
    two_seeds = demo.step_plan(demo.DemoSettings(minutes=1.0, backbone_share=0.5, steps=None), torch.device("cpu"))
    assert two_seeds["semattnet"] == (40, 20)  # the default trains two seeds; the budget covers both
    monkeypatch.setattr(demo, "OVERHEAD", 2.0)  # real steps cost more than bare ones: fewer fit
    assert demo.step_plan(demo.DemoSettings(minutes=1.0, backbone_share=0.5, steps=None), torch.device("cpu"))[
        "semattnet"
    ] == (
        20,
        10,
    )
