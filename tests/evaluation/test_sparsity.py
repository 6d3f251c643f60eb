"""The sparsity robustness sweep: settings, thinning, the frame loop it runs, files and the CLI."""

from __future__ import annotations

import csv
import json
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from semattnet._utils.outputs import OutputError
from semattnet.baselines.classical import ClassicalCompleter
from semattnet.cli import main
from semattnet.data.io import clamp_for_png, quantize_depth
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.evaluation.protocols import eval_source
from semattnet.evaluation.sparsity import (
    FIELDS,
    SparsityError,
    ThinnedSource,
    parse_settings,
    run_sparsity_sweep,
    sweep_model,
    thin,
)
from semattnet.synthetic.tree import write_synthetic_kitti

SETTINGS = ["beams=64,32,16,8", "keep=1,0.5,0.1"]


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("sparsity") / "kitti"
    write_synthetic_kitti(root, 2, (64, 160), seed=5, eval_frames=2, workers=1)
    return root


def test_parse_settings() -> None:
    assert parse_settings(["beams=64,8", "keep=1,0.25"]) == ["beams=64", "beams=8", "keep=1", "keep=0.25"]
    for bad, msg in [
        ("beams=12", "must divide 64"),
        ("keep=0", r"must be in \(0, 1\]"),
        ("keep=x", "bad value"),
        ("rings=8", "expected beams="),
        ("beams", "expected beams="),
        ("beams=", "expected"),
    ]:
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


def _by_hand(tree: Path, setting: str, stored: bool) -> tuple[float, dict[str, float]]:
    """The classical completion's density and metrics on ``setting``, frame by frame as the sweep's own loop
    did before it ran through ``complete_frames`` (frame ``i`` thinned with seed ``i``): on the unquantised
    depth, or (``stored``) on what its 16-bit PNG stores."""
    source, metrics, dens = eval_source("kitti-dc", tree, "val_select"), KittiMetrics(keep_per_image=False), []
    for i, name in enumerate(source.names):
        frame = source.load(name)
        sparse = thin(frame.sparse, setting, seed=i)
        dens.append(float((sparse > 0).mean()))
        depth = ClassicalCompleter()(frame.rgb, sparse).depth
        depth = quantize_depth(clamp_for_png(depth)) if stored else np.asarray(depth, np.float32)
        metrics.update(torch.from_numpy(depth)[None, None], torch.from_numpy(frame.gt)[None, None])
    return float(np.mean(dens)), metrics.compute()


def test_the_sweep_scores_what_the_png_stores(tree: Path, tmp_path: Path) -> None:
    """Each row is the frame loop's score of the stored PNG; against the unquantised depth (the sweep before
    it ran through the one loop) RMSE and MAE move by at most the rounding to 1/256 m (half a step: 1.95 mm;
    on this tree by less than 0.04 mm), the density not at all."""
    settings = ["beams=64", "beams=8", "keep=0.5"]
    rows = run_sparsity_sweep(tree, "val_select", settings, {"classical": ClassicalCompleter()}, tmp_path / "o")
    half_step_mm = 1000 / 512
    for row, setting in zip(rows, settings, strict=True):
        density, stored = _by_hand(tree, setting, stored=True)
        assert row["density"] == density  # the thinned input's mean density, as before
        for k in FIELDS[3:]:
            assert row[k] == pytest.approx(stored[k], rel=1e-9), (setting, k)
        _, raw = _by_hand(tree, setting, stored=False)
        for k in ("rmse_mm", "mae_mm"):  # moved by the quantisation only, within half a 1/256 m step
            assert abs(row[k] - raw[k]) <= half_step_mm, (setting, k, row[k], raw[k])


def test_the_sweep_is_deterministic_and_leaves_only_its_files(tree: Path, tmp_path: Path) -> None:
    one = run_sparsity_sweep(tree, "val_select", ["keep=0.5,0.1"], {"classical": ClassicalCompleter()}, tmp_path / "a")
    two = run_sparsity_sweep(tree, "val_select", ["keep=0.5,0.1"], {"classical": ClassicalCompleter()}, tmp_path / "b")
    assert one == two
    for out in (tmp_path / "a", tmp_path / "b"):  # no journal, no stage of the runs
        assert sorted(p.name for p in out.iterdir()) == ["sparsity.csv", "sparsity.json", "sparsity.png"]
    seeded = run_sparsity_sweep(
        tree, "val_select", ["keep=0.5"], {"classical": ClassicalCompleter()}, tmp_path / "c", seed=7
    )
    assert seeded[0]["rmse_mm"] != one[0]["rmse_mm"]  # another seed, other points


def test_thinned_source_is_the_frames_thinned_per_frame(tree: Path) -> None:
    source = eval_source("kitti-dc", tree, "val_select")
    thinned = ThinnedSource(source, "keep=0.5", seed=3)
    assert thinned.names == list(source.names) and thinned.inputs() == source.inputs()
    assert thinned.palette == source.palette
    for i, name in enumerate(source.names):
        frame, thin_frame = source.load(name), thinned.load(name)
        assert np.array_equal(thin_frame.sparse, thin(frame.sparse, "keep=0.5", seed=3 + i))
        assert np.array_equal(thin_frame.rgb, frame.rgb) and np.array_equal(thin_frame.gt, frame.gt)
        assert np.array_equal(thinned.load(name).sparse, thin_frame.sparse)  # the same points every time
    assert not np.array_equal(
        thinned.load(source.names[0]).sparse, ThinnedSource(source, "keep=0.5").load(source.names[0]).sparse
    )
    for bad, msg in [("keep=0.5,0.1", "one setting"), ("beams=12", "must divide 64")]:
        with pytest.raises(SparsityError, match=msg):
            ThinnedSource(source, bad)


def test_sweep_model_loads_the_model_after_every_check(tree: Path, tmp_path: Path) -> None:
    called = []

    def model() -> torch.nn.Module:
        called.append(1)
        raise AssertionError("loaded before the checks")

    with pytest.raises(OutputError, match="input folder"):
        sweep_model(tree, "val_select", ["keep=1"], model, tree / "sweep")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "mine.txt").write_text("x")
    with pytest.raises(FileExistsError, match="--overwrite"):
        sweep_model(tree, "val_select", ["keep=1"], model, tmp_path / "full")
    assert not called
