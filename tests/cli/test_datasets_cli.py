"""``--dataset nyuv2|void`` end to end through the CLI on tiny trees in the real layouts: data check, train
(a few steps, width 0.125), evaluate (the protocol's metrics), predict (a dataset root) and the sparsity sweep."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import read_depth
from tests.data._datasets import make_nyu, make_void

pytest.importorskip("h5py")


def run(*args: object, code: int = 0) -> str:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == code, result.output + repr(result.exception)
    return result.output


@pytest.fixture(scope="module")
def trees(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    t = tmp_path_factory.mktemp("datasets")
    nyu = make_nyu(t / "nyu", train=2, test=2, label=True)
    void = make_void(t / "void", train=2, test=2, h=64, w=96)
    return {"nyuv2": nyu, "void": void / "void_1500"}


# nyuv2 trains and scores at 256x320 (the protocol's 228x304, padded): ~20 s on one core, so marked slow
@pytest.mark.parametrize("dataset", [pytest.param("nyuv2", marks=pytest.mark.slow), "void"])
def test_check_train_evaluate_predict(dataset: str, trees: dict[str, Path], tmp_path: Path) -> None:
    root = trees[dataset]
    assert "ok" in run("data", "check", "--dataset", dataset, root)
    run(
        "train",
        "--dataset",
        dataset,
        "--data",
        root,
        "--out",
        tmp_path / "run",
        "--width",
        "0.125",
        "--batch-size",
        "2",
        "--workers",
        "0",
        "--max-steps",
        "2",
        "--set",
        "depth_head_init=[2,2]",
    )
    cfg = json.loads((tmp_path / "run" / "config.json").read_text())
    assert cfg["dataset"] == dataset and cfg["epochs"] == (25 if dataset == "nyuv2" else 10)  # the recipe
    ckpt = tmp_path / "run" / "checkpoints" / "last.pt"
    from semattnet.weights.checkpoint import load_checkpoint

    assert load_checkpoint(ckpt).config.palette == ("nyu40" if dataset == "nyuv2" else "cityscapes")
    out = run(
        "evaluate",
        "--dataset",
        dataset,
        "--checkpoint",
        ckpt,
        "--data",
        root,
        "--workers",
        "0",
        "--out",
        tmp_path / "ev",
        "--save-predictions",
    )
    metrics = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert metrics["dataset"] == dataset and metrics["split"] == "test" and metrics["images"] == 2
    if dataset == "nyuv2":
        assert "REL" in out and "d<1.25" in out and 0 <= metrics["delta1"] <= 1
        size = (228, 304)  # the protocol's crop: padding to 256x320 cropped back
    else:
        assert "iRMSE [1/km]" in out and metrics["mae_mm"] > 0
        size = (64, 96)
    preds = sorted((tmp_path / "ev" / "predictions").glob("*.png"))
    assert len(preds) == 2 and read_depth(preds[0]).shape == size
    run("predict", "--dataset", dataset, "--data", root, "--checkpoint", ckpt, "--out", tmp_path / "pred")
    assert len(list((tmp_path / "pred").glob("*.png"))) >= 2
    run(
        "evaluate",
        "--dataset",
        dataset,
        "--data",
        root,
        "--method",
        "classical",
        "--sparsity",
        "keep=1,0.5",
        "--out",
        tmp_path / "sweep",
    )
    rows = json.loads((tmp_path / "sweep" / "sparsity.json").read_text())
    assert [r["setting"] for r in rows] == ["keep=1", "keep=0.5"]


def test_palette_mismatch_is_one_line(trees: dict[str, Path], tmp_path: Path) -> None:
    """A Cityscapes-palette model refuses NYU-40 maps (the NYU tree's labels), before any work."""
    import semattnet
    from semattnet.weights.checkpoint import save_safetensors

    ckpt = tmp_path / "city.safetensors"  # a state dict: its config (no palette recorded) loads as cityscapes
    save_safetensors(semattnet.build_model("semattnet_backbone", width=0.125).state_dict(), ckpt)
    sweep = ["evaluate", "--sparsity", "keep=1", "--out", tmp_path / "s"]
    for cmd in (["evaluate", "--workers", "0"], ["predict", "--out", tmp_path / "p"], sweep):
        out = run(*cmd, "--dataset", "nyuv2", "--data", trees["nyuv2"], "--checkpoint", ckpt, code=1)
        assert "NYU-40 palette, but the model was trained with the Cityscapes palette" in out
        assert "Traceback" not in out and len(out.strip().splitlines()) == 1
    assert not (tmp_path / "p").exists() and not any((tmp_path / "s").iterdir())  # the sweep: no file, no stage
    run(
        *sweep,
        "--overwrite",
        "--dataset",
        "nyuv2",
        "--data",
        trees["nyuv2"],
        "--checkpoint",
        ckpt,
        "--palette-mismatch",
        "recolour",
    )  # the sweep converts maps as evaluate does
    rows = json.loads((tmp_path / "s" / "sparsity.json").read_text())
    assert [r["method"] for r in rows] == ["semattnet", "classical"]


def test_unknown_dataset_lists_the_valid_ones(trees: dict[str, Path]) -> None:
    out = run("data", "check", "--dataset", "nyu", trees["nyuv2"], code=2)
    assert "kitti-dc" in out and "nyuv2" in out and "void" in out
