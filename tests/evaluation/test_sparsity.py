"""The sparsity robustness sweep: settings, thinning, files and the CLI."""

from __future__ import annotations

import csv
import json
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.baselines.classical import ClassicalCompleter
from semattnet.cli import main
from semattnet.data.synthetic.tree import write_synthetic_kitti
from semattnet.evaluation.sparsity import FIELDS, SparsityError, parse_settings, run_sparsity_sweep, thin

SETTINGS = ["beams=64,32,16,8", "keep=1,0.5,0.1"]


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("sparsity") / "kitti"
    write_synthetic_kitti(root, 2, (64, 160), seed=5, eval_frames=2, workers=1)
    return root


def test_parse_settings() -> None:
    assert parse_settings(["beams=64,8", "keep=1,0.25"]) == ["beams=64", "beams=8", "keep=1", "keep=0.25"]
    for bad, msg in [("beams=12", "must divide 64"), ("keep=0", r"must be in \(0, 1\]"), ("keep=x", "bad value"),
                     ("rings=8", "expected beams="), ("beams", "expected beams="), ("beams=", "expected")]:  # fmt: skip
        with pytest.raises(SparsityError, match=msg):
            parse_settings([bad])


def test_thin_reduces_density() -> None:
    sparse = np.zeros((64, 200), np.float32)
    sparse[2::2, :] = 10.0  # 31 lines
    dens = [float((thin(sparse, f"beams={n}") > 0).mean()) for n in (64, 32, 16, 8)]
    assert dens[0] == pytest.approx(float((sparse > 0).mean())) and all(a > b for a, b in pairwise(dens))
    kept = thin(sparse, "keep=0.5", seed=1)
    assert (kept > 0).sum() == round(0.5 * (sparse > 0).sum()) and np.array_equal(kept, thin(sparse, "keep=0.5", 1))


def test_sweep_writes_rows_csv_json_png(tree: Path, tmp_path: Path) -> None:
    rows = run_sparsity_sweep(tree, "val_select", SETTINGS, {"classical": ClassicalCompleter()}, tmp_path / "o")
    assert [r["setting"] for r in rows] == parse_settings(SETTINGS)
    assert all(r["method"] == "classical" and np.isfinite([r[k] for k in FIELDS[2:]]).all() for r in rows)
    dens = {r["setting"]: r["density"] for r in rows}
    beams = [dens[f"beams={n}"] for n in (64, 32, 16, 8)]
    keep = [dens[f"keep={k}"] for k in ("1", "0.5", "0.1")]
    assert all(a > b for a, b in pairwise(beams)) and all(a > b for a, b in pairwise(keep))
    assert dens["beams=64"] == pytest.approx(dens["keep=1"])
    with open(tmp_path / "o" / "sparsity.csv") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == list(FIELDS) and len(table) == len(rows)
    assert json.loads((tmp_path / "o" / "sparsity.json").read_text()) == rows
    png = (tmp_path / "o" / "sparsity.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_sweep_and_one_line_errors(tree: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    args = ["evaluate", "--data", str(tree), "--method", "classical", "--out", str(tmp_path / "c")]
    ok = runner.invoke(main, [*args, "--sparsity", "beams=64,16", "--sparsity", "keep=0.5"])
    assert ok.exit_code == 0, ok.output
    assert "beams=16" in ok.output and (tmp_path / "c" / "sparsity.png").is_file()
    for bad, msg in [("beams=12", "must divide 64"), ("keep=2", "must be in"), ("dens=3", "expected beams=")]:
        res = runner.invoke(main, [*args, "--overwrite", "--sparsity", bad])
        assert res.exit_code != 0 and msg in res.output
        assert len(res.output.strip().splitlines()) == 1, res.output
    res = runner.invoke(main, ["evaluate", "--data", str(tree), "--sparsity", "keep=1", "--out", str(tmp_path / "d")])
    assert res.exit_code != 0 and "--checkpoint or --weights" in res.output
