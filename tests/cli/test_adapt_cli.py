"""``semattnet adapt`` end to end: on the bundled KITTI raw drive (stereo partner: the photometric loss runs), on a
folder of frames with a bad one (skipped and counted, exit status 3; the result read by ``predict --weights``), and
its one-line errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import write_depth, write_image

DRIVE = Path(__file__).resolve().parents[1] / "data/kitti_sample/kitti_raw/2011_09_26/2011_09_26_drive_0035_sync"
TINY = ["--crop", "32x64", "--batch-size", "1", "--steps", "1", "--device", "cpu"]

pytestmark = pytest.mark.filterwarnings("ignore:no semantic maps given")


def _run(*args: object) -> Any:
    return CliRunner().invoke(main, list(map(str, args)))


def test_adapt_on_the_kitti_raw_drive_uses_the_stereo_partner(tiny_weights: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = _run("adapt", "--kitti-raw", DRIVE, "--weights", tiny_weights, "--out", out, *TINY)
    assert res.exit_code == 0, res.output
    assert "done: step 1 on 1 frame(s)" in res.output
    assert {p.name for p in out.iterdir()} == {"adapted.safetensors", "checkpoints", "log.json"}
    step = json.loads((out / "log.json").read_text())["steps"][0]
    assert {"sparse", "photometric", "smoothness"} <= set(step) and step["photometric"] > 0
    again = _run("adapt", "--kitti-raw", DRIVE, "--weights", tiny_weights, "--out", out, *TINY)
    assert again.exit_code == 1 and "already holds an adaptation run" in again.output and "--overwrite" in again.output


def _folder(root: Path, bad: str) -> tuple[Path, Path]:
    rgb, sparse = root / "rgb", root / "sparse"
    rgb.mkdir(parents=True)
    sparse.mkdir()
    for i in range(3):
        rng = np.random.default_rng(i)
        write_image(rgb / f"f{i}.png", rng.integers(0, 256, (32, 64, 3), dtype=np.uint8))
        depth = np.where(rng.random((32, 64)) < 0.2, rng.uniform(2, 40, (32, 64)), 0).astype(np.float32)
        write_depth(sparse / f"f{i}.png", depth)
    (sparse / f"{bad}.png").write_bytes(b"not a png at all")
    return rgb, sparse


@pytest.mark.slow  # seconds: adapt then predict; the drive's test above runs adapt end to end by default
@pytest.mark.filterwarnings("ignore:.*hole\\(s\\)", "ignore:clamped")
def test_adapt_on_a_folder_skips_and_counts_a_bad_frame_and_predict_reads_the_result(
    tiny_weights: Path, tmp_path: Path
) -> None:
    rgb, sparse = _folder(tmp_path / "frames", bad="f1")
    out = tmp_path / "run"
    res = _run("adapt", "--rgb", rgb, "--sparse", sparse, "--weights", tiny_weights, "--out", out, *TINY)
    assert res.exit_code == 3, res.output
    assert "f1: skipped: " in res.output and "f1.png" in res.output and "1 frame(s) skipped" in res.output
    assert json.loads((out / "log.json").read_text())["skipped"][0]["name"] == "f1"
    pred = tmp_path / "pred"
    done = _run("predict", "--rgb", rgb, "--sparse", sparse, "--weights", out / "adapted.safetensors", "--out", pred)
    assert done.exit_code == 3 and (pred / "f0.png").is_file(), done.output  # f1 skipped there too


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--crop", "30x64"], "multiples of 32"),
        (["--hide", "1.5"], "--hide"),
        (["--loss", "sparse,depth"], "--loss"),
        (["--hide", "a..b"], "--hide"),
    ],
)
def test_adapt_options_are_checked_before_any_work(
    tiny_weights: Path, tmp_path: Path, args: list[str], message: str
) -> None:
    res = _run("adapt", "--kitti-raw", DRIVE, "--weights", tiny_weights, "--out", tmp_path / "run", *args)
    assert res.exit_code == 2 and message in res.output, res.output
    assert not (tmp_path / "run").exists()


def test_adapt_needs_weights_unless_it_resumes(tmp_path: Path) -> None:
    res = _run("adapt", "--kitti-raw", DRIVE, "--out", tmp_path / "run")
    assert res.exit_code == 2 and "--weights is required" in res.output
