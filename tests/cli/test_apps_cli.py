"""The command line, end to end on tiny inputs."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

import semattnet
from semattnet.cli import main


@pytest.mark.slow  # ~10 s; tests/apps/test_demo.py runs the demo by default
def test_demo_cli(tmp_path: Path) -> None:
    args = [
        "demo",
        "--out",
        str(tmp_path),
        "--size",
        "64x128",
        "--frames",
        "6",
        "--eval-frames",
        "2",
        "--steps",
        "2,1",
        "--device",
        "cpu",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "Report: " in result.output and (tmp_path / "report.html").is_file()
    metrics = json.loads((tmp_path / "metrics.json").read_text())["metrics"]
    # the live models, the baselines and the shipped reference checkpoint (scored on the same held-out scenes)
    assert set(metrics) == {"sparse", "classical", "two_branch", "semattnet", "reference"}
    again = CliRunner().invoke(main, args)  # never overwrites a previous report silently
    assert again.exit_code != 0 and "--overwrite" in again.output
    bad = CliRunner().invoke(main, [*args[:-4], "--steps", "x", "--overwrite"])
    assert bad.exit_code != 0 and "BACKBONE,FULL" in bad.output


def test_ablate_cli_resumes(tmp_path: Path) -> None:
    base = [
        "ablate",
        "--out",
        str(tmp_path),
        "--size",
        "32x64",  # as tests/apps/test_ablate.py: resuming is the point, not the size
        "--frames",
        "4",
        "--eval-frames",
        "2",
        "--seeds",
        "0",
        "--backbone-steps",
        "2",
        "--full-steps",
        "1",
        "--device",
        "cpu",
    ]
    first = CliRunner().invoke(main, [*base, "--configs", "table2_a"])
    assert first.exit_code == 0, first.output
    done = tmp_path / "results" / "table2_a_seed0.json"
    stamp = done.stat().st_mtime_ns
    second = CliRunner().invoke(main, [*base, "--configs", "table2_a,table2_c"])
    assert second.exit_code == 0, second.output
    assert done.stat().st_mtime_ns == stamp  # finished runs are not redone
    summary = json.loads((tmp_path / "ablation.json").read_text())["configs"]
    assert set(summary) == {"table2_a", "table2_c"}
    for row in summary.values():
        assert {"all", "shadowed", "unshadowed", "per_seed"} <= set(row) and row["all"]["mean"] > 0
    assert "| table2_c |" in (tmp_path / "ablation.md").read_text()
    typo = CliRunner().invoke(main, [*base, "--configs", "table2_z"])
    assert typo.exit_code != 0 and "unknown configuration 'table2_z'" in typo.output


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
