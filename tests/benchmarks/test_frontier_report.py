"""benchmarks/frontier_report.py: the frontier's table, the acceptance read from it and the docs section, from a
hand-made results.json and timing.json."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from semattnet._errors import InputError
from tests.benchmarks._scripts import BENCHMARKS, load_script


@pytest.fixture(scope="module")
def report() -> ModuleType:
    return load_script("frontier_report")


def _scores(rmse: float, mae: float, irmse: float, imae: float) -> dict[str, float]:
    return {"rmse": rmse, "mae": mae, "irmse": irmse, "imae": imae}


def _results() -> dict[str, Any]:
    """Metres and 1/m, as the training half writes them; the real-time variant trained with two seeds."""
    rt = {"0": _scores(1.1, 0.5, 0.004, 0.0019), "1": _scores(1.3, 0.5, 0.004, 0.0021)}
    return {
        "seeds": [0, 1],
        "recipe": {"train_frames": 400, "size": [96, 320]},
        "results": {
            "classical": {"scores": _scores(2.0, 0.9, 0.01, 0.004), "uncertainty": {"ause_rmse": 0.5}},
            "paper_w1_8": {
                "params": 2_000_000,
                "scores": _scores(1.1, 0.4, 0.003, 0.0015),
                "per_seed": {"0": _scores(1.1, 0.4, 0.003, 0.0015)},
                "uncertainty": {"ause_rmse": 0.2},
            },
            "semattnet_rt_s": {
                "params": 150_000,
                "scores": _scores(1.2, 0.5, 0.004, 0.002),
                "per_seed": rt,
                "uncertainty": {"ause_rmse": 0.3},
            },
        },
    }


def _timing(rt_ms: float = 80.0) -> dict[str, Any]:
    rows = {
        "paper_w1_8/torch-f32": {"ms": 800.0, "ratio": 1.0, "peak_mb": 900.0, "growth_mb": 400.0},
        "paper_w1_8/openvino-f32": {"ms": 510.0, "ratio": 1.0, "peak_mb": 700.0, "growth_mb": 300.0},
        "semattnet_rt_s/torch-f32": {"ms": 150.0, "ratio": 0.19, "peak_mb": 500.0, "growth_mb": 120.0},
        "semattnet_rt_s/openvino-f32": {"ms": 95.0, "ratio": 0.19, "peak_mb": 450.0, "growth_mb": 100.0},
        "semattnet_rt_s/openvino-int8": {"ms": rt_ms, "ratio": 0.2, "peak_mb": 400.0, "growth_mb": 90.0},
        "semattnet_rt_s/openvino-f32-avx2": {"ms": 105.0, "ratio": 0.2},  # --isa-cap AVX2: no memory figure
    }
    change = {"rmse": 0.004, "mae": -0.002, "irmse": 0.008, "imae": 0.001}
    return {
        "cpu": "Test CPU",
        "threads": 2,
        "isa": ["avx2", "fma"],
        "size": [352, 1216],
        "repeats": 5,
        "memory": "growth",
        "models": {
            "paper_w1_8": {"gmac": 8.2, "params": 2_000_000},
            "semattnet_rt_s": {"gmac": 0.95, "params": 150_000},
        },
        "rows": rows,
        "classical_ms": 30.0,
        "frames": {
            "paper_w1_8": {"frame_ms": 600.0},
            "semattnet_rt_s": {"frame_ms": 140.0, "stages_ms": {"read": 10.0, "network": 110.0, "writing": 20.0}},
        },
        "int8": {"semattnet_rt_s": {"change": change}},
    }


def test_table_rows_in_kitti_units_with_the_seeds_spread(report: ModuleType) -> None:
    lines = report.table(_results(), _timing()).splitlines()
    assert lines[0].startswith("| variant | GMAC | params | RMSE [mm] |") and "OV int8 [ms]" in lines[0]
    assert len(lines) == 2 + 3 and lines[1].count("|") == lines[0].count("|")
    rt = next(line for line in lines if line.startswith("| `semattnet_rt_s` |"))
    cells = [c.strip() for c in rt.strip("|").split("|")]
    # GMAC, params, RMSE (mean ± half the range), MAE, iRMSE, iMAE, AUSE
    assert cells[1:8] == ["0.95", "0.15 M", "1200 ± 100", "500", "4.0", "2.0 ± 0.1", "0.300"]
    assert cells[8:] == ["150", "95", "80", "105", "140", "90 / 400"]  # torch, OV f32, int8, AVX2, frame, memory
    classical = [c.strip() for c in lines[2].strip("|").split("|")]
    assert classical[:4] == ["classical completion", "–", "–", "2000"] and classical[8:12] == ["30", "–", "–", "–"]
    paper = [c.strip() for c in lines[3].strip("|").split("|")]
    assert paper[0] == "paper model, width 1/8" and paper[10:12] == ["–", "–"] and paper[-1] == "300 / 700"  # no int8
    timing = _timing()
    timing["rows"]["paper_w1_8/openvino-f32"].update(peak_mb=float("nan"), growth_mb=float("nan"))  # its run failed
    assert report.table(_results(), timing).splitlines()[3].endswith("| 600 | – |")
    results = _results()
    results["results"]["semattnet_rt_s"]["affinity"] = "convex"  # the propagation kernel it was trained with
    assert "| `semattnet_rt_s` (convex kernel) |" in report.table(results, _timing())


def test_verdict_reads_the_acceptance(report: ModuleType) -> None:
    text = report.verdict(_results(), _timing(), "semattnet_rt_s")
    assert "80 ms network + propagation (OV int8), within the 100 ms budget; 105 ms with AVX2 kernels only;" in text
    assert "beats the classical completion on all four metrics" in text
    assert "RMSE +9.1 % against the width-1/8 paper model (within 15 %)" in text
    assert "int8 within 1 % of float32 (largest change +0.8 %, IRMSE)" in text
    results = _results()
    results["results"]["classical"]["scores"]["imae"] = 0.001
    slow = report.verdict(results, _timing(rt_ms=120.0), "semattnet_rt_s")
    assert "95 ms" in slow and "(OV f32)" in slow  # the fastest backend
    assert "does not beat the classical completion on IMAE" in slow
    assert report.passes(_results(), _timing(), "semattnet_rt_s")
    assert report.summary(_results(), _timing(), ["semattnet_rt_s"]).startswith("**Acceptance: met by `semattnet_rt_s`")
    assert not report.passes(results, _timing(), "semattnet_rt_s")  # worse iMAE than the classical completion
    timing = _timing(rt_ms=120.0)
    timing["rows"]["semattnet_rt_s/openvino-f32"]["ms"] = 101.0
    assert not report.passes(_results(), timing, "semattnet_rt_s")  # over the budget on every backend
    timing = _timing()
    timing["int8"]["semattnet_rt_s"]["change"]["mae"] = 0.02
    assert not report.passes(_results(), timing, "semattnet_rt_s")  # int8 2 % off float32
    assert "no real-time variant meets all of it" in report.summary(_results(), timing, ["semattnet_rt_s"])


def test_bound_names_the_best_reached_and_where_its_frame_goes(report: ModuleType) -> None:
    timing = _timing(rt_ms=130.0)
    timing["rows"]["semattnet_rt_s/openvino-f32"]["ms"] = 125.0
    text = report.bound(timing, ["semattnet_rt_s"])
    assert text.startswith("No real-time variant is within the 100 ms budget: the best reached is 125 ms")
    assert "network 110 ms" in text and "0.95 GMAC at 15 GFLOP/s." in text
    timing["conv_peak_gflops"] = 152.0
    assert "0.95 GMAC at 15 GFLOP/s, 10 % of the float32 convolution peak measured here (152 GFLOP/s)" in report.bound(
        timing, ["semattnet_rt_s"]
    )
    assert report.bound(_timing(), ["semattnet_rt_s"]).startswith("Fastest: `semattnet_rt_s`, 80 ms (OV int8)")


def _run(tmp_path: Path) -> tuple[Path, Path]:
    out, docs = tmp_path / "run", tmp_path / "docs"
    out.mkdir()
    docs.mkdir()
    (out / "results.json").write_text(json.dumps(_results()))
    (out / "timing.json").write_text(json.dumps(_timing()))
    return out, docs


def test_report_replaces_only_the_text_between_the_markers(
    report: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """What --report runs (with the plot: the tiny --all run, slow; matplotlib's import alone is seconds)."""
    out, docs = _run(tmp_path)
    doc = docs / "performance.md"
    doc.write_text(f"# Title\n\nbefore\n\n{report.BEGIN}\nold table\n{report.END}\n\nafter\n")
    plotted: list[Path] = []
    monkeypatch.setattr(report, "plot", lambda results, timing, path: plotted.append(path))
    report.write_report(out, doc, docs / "frontier.png")
    text = doc.read_text()
    assert text.startswith("# Title\n\nbefore\n\n" + report.BEGIN) and text.endswith(report.END + "\n\nafter\n")
    assert "old table" not in text and "**Test CPU, 2 threads (ISA: avx2, fma)**" in text
    assert "![RMSE against milliseconds, log scale](frontier.png)" in text
    assert plotted == [docs / "frontier.png"]
    doc.write_text("# no markers\n")
    with pytest.raises(InputError, match="frontier markers are missing"):
        report.write_report(out, doc, docs / "frontier.png")
    (out / "timing.json").unlink()
    with pytest.raises(InputError, match=r"timing.json is missing: run the training half, then --time"):
        report.write_report(out, doc, docs / "frontier.png")


def test_the_docs_page_holds_the_markers_and_the_command(report: ModuleType) -> None:
    text = (BENCHMARKS.parent / "docs" / "performance.md").read_text()
    assert text.count(report.BEGIN) == 1 and text.count(report.END) == 1
    assert "python benchmarks/frontier.py --out frontier-run --report" in text
