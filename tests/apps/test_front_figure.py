"""The front-page figure's command on a tiny configuration: the shipped weights and the classical completion,
swept and scored for their uncertainty, drawn, and the numbers written beside the picture."""

from __future__ import annotations

import json
import runpy
import sys
from pathlib import Path

import pytest

from semattnet.apps.demo.recipe import DemoSettings
from semattnet.apps.front_figure import FIGURE_WEIGHTS, make_front_figure


@pytest.mark.slow  # two shipped models and the classical completion, swept and scored: about a minute on 2 cores
def test_tiny_front_figure(tmp_path: Path) -> None:
    tiny = DemoSettings(train_frames=1, eval_frames=2, size=(64, 96))
    numbers = make_front_figure(
        tmp_path / "out", tmp_path / "work", ("beams=64", "keep=0.5"), demo=tiny, log=lambda _: None
    )
    png = tmp_path / "out" / "sparsity-sweep.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    saved = json.loads((tmp_path / "out" / "sparsity-sweep.json").read_text())
    assert saved == json.loads(json.dumps(numbers))
    methods = [*FIGURE_WEIGHTS, "classical completion"]
    assert sorted({r["method"] for r in saved["sweep"]}) == sorted(methods)
    assert {r["setting"] for r in saved["sweep"]} == {"beams=64", "keep=0.5"}
    for name in methods:
        scores = saved["uncertainty"][name]
        assert set(scores) == {"ause_rmse", "aurg_rmse", "ause_mae", "aurg_mae"}
        assert scores["ause_rmse"] >= 0  # the oracle is the best ordering there is


def test_the_script_is_the_documented_command(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    script = Path(__file__).resolve().parents[2] / "scripts" / "docs-figures.py"
    assert "scripts/docs-figures.py --out docs" in (script.parents[1] / "Makefile").read_text()
    monkeypatch.setattr(sys, "argv", [str(script), "--help"])
    with pytest.raises(SystemExit) as done:
        runpy.run_path(str(script), run_name="__main__")
    assert done.value.code == 0
