"""``semattnet predict --stream`` stopped by SIGTERM: the frames handed to the writer are written and journaled
first, the exit status is 143, and ``--resume`` finishes the run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from semattnet.data.io import write_depth, write_image

FRAMES = 60


def _folder(root: Path) -> tuple[Path, Path]:
    rgb, sparse = root / "rgb", root / "sparse"
    rng = np.random.default_rng(0)
    for i in range(FRAMES):
        write_image(rgb / f"f{i:03d}.png", rng.integers(0, 256, (16, 24, 3), dtype=np.uint8))
        depth = np.zeros((16, 24), np.float32)
        depth[::3, ::3] = rng.uniform(1, 50, depth[::3, ::3].shape)
        write_depth(sparse / f"f{i:03d}.png", depth)
    return rgb, sparse


@pytest.mark.slow  # two processes (the stopped run, the resumed one): 26 s on 2 busy cores
def test_sigterm_drains_the_writer_then_resume_finishes(tmp_path: Path) -> None:
    rgb, sparse = _folder(tmp_path)
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "semattnet",
        "predict",
        "--rgb",
        str(rgb),
        "--sparse",
        str(sparse),
        "--method",
        "classical",
        "--out",
        str(out),
        "--stream",
    ]
    src = str(Path(__file__).resolve().parents[2] / "src")
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    assert proc.stdout is not None
    written = 0
    for line in proc.stdout:  # a few frames done: the writer is busy with the next ones
        written += " -> " in line
        if written == 5:
            proc.send_signal(signal.SIGTERM)
            break
    rest = proc.communicate(timeout=60)[0]
    assert proc.returncode == 143, rest
    doc = json.loads((out / "frames.json").read_text())
    done = [e["name"] for e in doc["frames"] if e["status"] == "done"]
    assert not doc["complete"] and 5 <= len(done) < FRAMES, rest
    assert all((out / f"{n}.png").is_file() and (out / f"{n}_color.png").is_file() for n in done)
    resumed = subprocess.run([*cmd, "--resume"], capture_output=True, text=True, env=env, timeout=120)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert f"resuming: {len(done)} of {FRAMES} frame(s) already done" in resumed.stdout
    doc = json.loads((out / "frames.json").read_text())
    assert doc["complete"] and all(e["status"] == "done" for e in doc["frames"])
