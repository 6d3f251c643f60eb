"""``evaluate`` under torchrun with two CPU processes: the files and metrics of one process,
each frame scored once when the frame count does not divide by the number of processes."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

import semattnet
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.weights.checkpoint import save_safetensors
from tests.inference.test_sharding import assert_one_line_error, cli, rank_logs, tree_bytes


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("dist-eval-data")
    write_synthetic_kitti(out, frames=1, size=(64, 96), seed=3, eval_frames=5, workers=1)
    return out


@pytest.fixture(scope="module")
def weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    model = semattnet.build_model("semattnet", width=0.125)
    model.backbone.init_depth_heads()
    return save_safetensors(model.state_dict(), tmp_path_factory.mktemp("w") / "tiny.safetensors")


@pytest.mark.slow  # ~1 min (three torchrun launches); predict's two-process tests run by default
def test_evaluate_two_processes_equals_one(tree: Path, weights: Path, tmp_path: Path) -> None:
    common = (
        "evaluate",
        "--checkpoint",
        weights,
        "--data",
        tree,
        "--device",
        "cpu",
        "--workers",
        "0",
        "--save-predictions",
        "--pictures",
        "3",
    )
    one = cli(*common, "--out", tmp_path / "one")
    assert one.returncode == 0, one.stderr[-3000:]
    res = cli(*common, "--out", tmp_path / "two", nproc=2, logs=tmp_path / "logs")
    assert res.returncode == 0, res.stderr[-3000:]
    a, b = tree_bytes(tmp_path / "one"), tree_bytes(tmp_path / "two")
    assert a.keys() == b.keys() and len([k for k in a if k.startswith("predictions/")]) == 5
    assert len([k for k in a if k.startswith("pictures/")]) == 3
    binary = [k for k in a if k != "metrics.json"]
    assert [k for k in binary if a[k] != b[k]] == []  # PNGs and per_image.csv byte for byte
    m1, m2 = (json.loads(x["metrics.json"]) for x in (a, b))
    assert m1.keys() == m2.keys() and m2["images"] == 5  # 3 + 2 frames: none counted twice
    for k, v in m1.items():
        assert m2[k] == (v if isinstance(v, str) else pytest.approx(v, rel=1e-9)), k
    rows = list(csv.DictReader(open(tmp_path / "two" / "per_image.csv")))
    assert len(rows) == 5 and len({r["name"] for r in rows}) == 5
    stdout = rank_logs(tmp_path / "logs", "stdout")
    assert "RMSE" in stdout[0] and stdout[1] == ""  # the table once, from rank 0

    again = cli(*common, "--out", tmp_path / "two", nproc=2, logs=tmp_path / "logs2")
    assert_one_line_error(again, tmp_path / "logs2", 2, "pass --overwrite")
    assert tree_bytes(tmp_path / "two") == b
