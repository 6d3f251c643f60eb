"""``semattnet adapt --resume``: an option given on the command line that differs from the run's (``--steps``,
``--lr``, ``--weights``) is refused in one line naming it and both values; the same values, or none (the defaults are
not compared), resume; a doctored state is one line naming the file, exit 1, never "a bug in semattnet"."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
import torch
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.weights.gate import DIGEST_KEY, tensor_digest
from tests.training._adapt_runs import digests, rt_checkpoint

DRIVE = Path(__file__).resolve().parents[1] / "data/kitti_sample/kitti_raw/2011_09_26/2011_09_26_drive_0035_sync"
TINY = ["--crop", "32x64", "--batch-size", "1", "--steps", "1", "--device", "cpu"]

pytestmark = pytest.mark.filterwarnings("ignore:no semantic maps given")


def _run(*args: object) -> Any:
    return CliRunner().invoke(main, list(map(str, args)))


@pytest.fixture
def run(tmp_path: Path) -> tuple[Path, Path]:
    """A run of one step on the bundled drive, from the smallest weights: (its folder, the weights)."""
    weights = rt_checkpoint(tmp_path / "rt.safetensors")
    out = tmp_path / "run"
    res = _run("adapt", "--kitti-raw", DRIVE, "--weights", weights, "--out", out, *TINY)
    assert res.exit_code == 0, res.output
    return out, weights


def _error_line(res: Any) -> str:
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 1 and "Traceback" not in res.output and "bug in semattnet" not in res.output, res.output
    return lines[-1]


def test_resume_refuses_options_that_differ_from_the_run_naming_both_values(
    run: tuple[Path, Path], tmp_path: Path
) -> None:
    out, weights = run
    other = tmp_path / "other.safetensors"
    shutil.copy(weights, other)
    before = digests(out)
    for args, said in [
        (["--steps", "3"], "--steps 3 differs from the run being resumed (--steps 1, in "),
        (["--lr", "0.01"], "--lr 0.01 differs from the run being resumed (--lr 0.0001, in "),
        (["--weights", other], f"--weights {other} differs from the run being resumed (--weights {weights}, in "),
    ]:
        line = _error_line(_run("adapt", "--kitti-raw", DRIVE, "--out", out, "--resume", *args))
        assert said in line and str(out / "checkpoints/last.pt") in line, line
    assert digests(out) == before
    same = _run(
        "adapt", "--kitti-raw", DRIVE, "--out", out, "--resume", "--steps", "1", "--lr", "1e-4", "--weights", weights
    )
    assert same.exit_code == 0 and "done: step 1" in same.output, same.output
    bare = _run("adapt", "--kitti-raw", DRIVE, "--out", out, "--resume")  # --steps' default (1000) is not compared
    assert bare.exit_code == 0 and "done: step 1" in bare.output, bare.output


def test_resume_from_a_doctored_state_is_one_line_naming_the_file(run: tuple[Path, Path]) -> None:
    out, _ = run
    state_path = out / "checkpoints/last.pt"
    state = torch.load(state_path, weights_only=True)
    state["scheduler"] = "garbage"
    state[DIGEST_KEY] = tensor_digest(state)
    torch.save(state, state_path)
    line = _error_line(_run("adapt", "--kitti-raw", DRIVE, "--out", out, "--resume"))
    assert line.startswith(f"Error: {state_path}: damaged adaptation state: scheduler"), line
