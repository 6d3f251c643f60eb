"""The command line, end to end on tiny inputs."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import torch
from click.testing import CliRunner
from PIL import Image

import semattnet
from semattnet.cli import main


def test_demo_smoke(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["demo", "--out", str(tmp_path), "--size", "64x128", "--steps", "3"])
    assert result.exit_code == 0, result.output
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert set(metrics["rmse_mm"]) >= {"fused_depth", "refined_depth"}
    depth = Image.open(tmp_path / "depth.png")
    assert depth.size == (128, 64) and depth.mode.startswith("I;16")
    assert Image.open(tmp_path / "panel.png").size[0] == 128


def test_console_script_is_installed() -> None:
    exe = shutil.which("semattnet") or str(Path(sys.executable).with_name("semattnet"))
    out = subprocess.run([exe, "--version"], capture_output=True, text=True, check=True)
    assert semattnet.__version__ in out.stdout


def test_models_lists_registry() -> None:
    result = CliRunner().invoke(main, ["models"])
    assert result.exit_code == 0
    assert "semattnet_backbone" in result.output and "table2_c" in result.output


def test_convert_and_info(tmp_path: Path) -> None:
    model = semattnet.build_model("semattnet_backbone", width=0.125)
    torch.save({"epoch": 3, "model": model.state_dict()}, tmp_path / "in.pth.tar")
    runner = CliRunner()
    result = runner.invoke(main, ["convert", str(tmp_path / "in.pth.tar"), str(tmp_path / "out.safetensors")])
    assert result.exit_code == 0, result.output
    again = runner.invoke(main, ["convert", str(tmp_path / "in.pth.tar"), str(tmp_path / "out.safetensors")])
    assert again.exit_code != 0 and "--overwrite" in again.output
    info = runner.invoke(main, ["info", str(tmp_path / "out.safetensors")])
    assert info.exit_code == 0 and "epoch:       3" in info.output and '"refine": false' in info.output


def test_bad_checkpoint_gives_one_line_error(tmp_path: Path) -> None:
    (tmp_path / "bad.pth").write_bytes(b"garbage")
    result = CliRunner().invoke(main, ["info", str(tmp_path / "bad.pth")])
    assert result.exit_code == 1
    assert result.output.startswith("Error: ") and "bad.pth" in result.output
    assert "Traceback" not in result.output
