"""``semattnet train --model NAME``: any registered architecture, an unknown name refused in one line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.models.registry import list_models
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.training.config import TrainConfig
from semattnet.weights.checkpoint import load_checkpoint


def _train(monkeypatch: pytest.MonkeyPatch, *args: str) -> tuple[int, str, list[TrainConfig]]:
    """``semattnet train ARGS`` with the trainer replaced by one that records its config."""
    seen: list[TrainConfig] = []

    def fake(cfg: TrainConfig, **kw: Any) -> dict[str, float]:
        seen.append(cfg)
        return {"epoch": 0, "step": 0, "best_rmse_mm": 0.0}

    monkeypatch.setattr("semattnet.training.trainer.train", fake)
    result = CliRunner().invoke(main, ["train", *args])
    return result.exit_code, result.output, seen


@pytest.mark.parametrize("name", ["semattnet_rt_s", "table2_g"])
def test_model_reaches_the_config(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, name: str) -> None:
    code, out, seen = _train(monkeypatch, "--model", name, "--out", str(tmp_path / "run"))
    assert code == 0, out
    assert [c.model for c in seen] == ["semattnet_rt_s" if name == "semattnet_rt_s" else "semattnet"]  # alias resolved


def test_default_model_is_the_paper_s(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    code, out, seen = _train(monkeypatch, "--out", str(tmp_path / "run"))
    assert code == 0, out
    assert seen[0].model == "semattnet"


def test_unknown_model_is_one_line_listing_the_names(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    code, out, seen = _train(monkeypatch, "--model", "semattnet_rt_xl", "--out", str(tmp_path / "run"))
    assert code == 1 and not seen
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: --model: unknown model 'semattnet_rt_xl'"), out
    assert all(name in lines[0] for name in list_models())


def test_model_with_resume_is_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    code, out, seen = _train(monkeypatch, "--resume", "--out", str(tmp_path), "--model", "semattnet_rt_s")
    assert code == 2 and not seen and "--model: a resumed run keeps its model" in out


@pytest.mark.slow  # ~17 s: two real steps; the tests above cover the option by default
def test_trains_a_real_time_model(tmp_path: Path) -> None:
    """Two real steps of ``semattnet_rt_s``: its checkpoint holds that architecture."""
    data = tmp_path / "data"
    write_synthetic_kitti(data, frames=2, size=(64, 128), seed=0, eval_frames=0, workers=1)
    args = [
        "train",
        "--model",
        "semattnet_rt_s",
        "--data",
        str(data),
        "--out",
        str(tmp_path / "run"),
        "--crop",
        "64x128",
        "--batch-size",
        "2",
        "--workers",
        "0",
        "--max-steps",
        "2",
        "--set",
        "val_split=",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    ckpt = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert (
        ckpt.config is not None and ckpt.config.encoder == "lite_s4"
    )  # semattnet_rt_s's encoder, not the paper's ResNet
    assert json.loads((tmp_path / "run" / "config.json").read_text())["model"] == "semattnet_rt_s"
