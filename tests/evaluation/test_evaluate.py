"""Evaluation, prediction, submission and pictures, end to end from the CLI."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import semattnet
from semattnet.cli import main
from semattnet.data.io import read_depth, read_image, write_image
from semattnet.evaluation.submission import SubmissionError, write_submission_files
from semattnet.inference.backends import EngineSpec
from semattnet.inference.completer import DepthCompleter
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.viz.depth import error_map
from semattnet.weights.checkpoint import save_safetensors
from tests._helpers import SAMPLE

SEL = "data_depth_selection/val_selection_cropped"


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("eval-data")
    write_synthetic_kitti(out, frames=4, size=(64, 128), seed=2, eval_frames=3, workers=1)
    return out


@pytest.fixture(scope="module")
def weights(tmp_path_factory) -> Path:
    model = semattnet.build_model("semattnet", width=0.125)
    model.backbone.init_depth_heads()
    return save_safetensors(model.state_dict(), tmp_path_factory.mktemp("w") / "tiny.safetensors")


def run(*args: str) -> str:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


def test_metrics_and_evaluate_agree(tree: Path, weights: Path, tmp_path: Path) -> None:
    out = tmp_path / "ev"
    run(
        "evaluate",
        "--checkpoint",
        weights,
        "--data",
        tree,
        "--out",
        out,
        "--save-predictions",
        "--pictures",
        "1",
        "--workers",
        "0",
    )
    ev = json.loads((out / "metrics.json").read_text())
    run("metrics", out / "predictions", tree / SEL / "groundtruth_depth", "--json", tmp_path / "m.json")
    folder = json.loads((tmp_path / "m.json").read_text())
    for k in ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"):
        assert folder[k] == pytest.approx(ev[k], rel=1e-9), k
    assert ev["images"] == 3
    rows = (out / "per_image.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[0].startswith("name,")
    assert len(list((out / "pictures").glob("*.png"))) == 1
    # the uncertainty's sparsification scores and curves (semattnet.evaluation.sparsification)
    assert {"ause_rmse", "aurg_rmse", "ause_mae", "aurg_mae"} <= set(ev) and ev["ause_rmse"] >= 0
    assert (out / "sparsification.png").stat().st_size > 0


def test_metrics_refuses_mismatched_folders(tree: Path, tmp_path: Path) -> None:
    gt = tree / SEL / "groundtruth_depth"
    pred = tmp_path / "pred"
    shutil.copytree(gt, pred)
    victim = sorted(pred.glob("*.png"))[0]
    victim.rename(pred / "stray.png")
    result = CliRunner().invoke(main, ["metrics", str(pred), str(gt)])
    assert result.exit_code == 1 and "stray.png" in result.output and victim.name in result.output
    (pred / "stray.png").rename(victim)
    from semattnet.data.io import write_depth

    write_depth(victim, np.ones((10, 10)), overwrite=True)
    result = CliRunner().invoke(main, ["metrics", str(pred), str(gt)])
    assert result.exit_code == 1 and "size mismatch" in result.output and victim.name in result.output


def test_train_evaluate_predict_submit_round_trip(tree: Path, tmp_path: Path) -> None:
    run(
        "train",
        "--data",
        tree,
        "--out",
        tmp_path / "run",
        "--width",
        "0.125",
        "--crop",
        "64x128",
        "--batch-size",
        "2",
        "--workers",
        "0",
        "--max-steps",
        "2",
        "--set",
        "depth_head_init=[10,15]",
    )
    ckpt = tmp_path / "run" / "checkpoints" / "last.pt"
    assert "RMSE" in run("evaluate", "--checkpoint", ckpt, "--data", tree, "--workers", "0")
    sel = tree / SEL
    out = run(
        "predict",
        "--checkpoint",
        ckpt,
        "--rgb",
        sel / "image",
        "--sparse",
        sel / "velodyne_raw",
        "--semantic",
        sel / "semantic",
        "--out",
        tmp_path / "pred",
    )
    assert out.count("->") == 0 or True
    # folder mode pairs by file name: velodyne files are named differently, so use the test split
    test = tree / "data_depth_selection/test_depth_completion_anonymous"
    run(
        "predict",
        "--checkpoint",
        ckpt,
        "--rgb",
        test / "image",
        "--sparse",
        test / "velodyne_raw",
        "--semantic",
        test / "semantic",
        "--out",
        tmp_path / "pred2",
        "--npy",
        "--panel",
    )
    assert sorted(p.name for p in (tmp_path / "pred2").iterdir())[:4] == [
        "0000000000.npy",
        "0000000000.png",
        "0000000000_color.png",
        "0000000000_panel.png",
    ]
    run("submit", "--checkpoint", ckpt, "--data", tree, "--out", tmp_path / "sub", "--expected-frames", "3")
    with zipfile.ZipFile(tmp_path / "sub.zip") as zf:
        assert sorted(zf.namelist()) == ["0000000000.png", "0000000001.png", "0000000002.png"]
    assert read_depth(tmp_path / "sub" / "0000000000.png").shape == (64, 128)
    again = CliRunner().invoke(
        main,
        [
            "submit",
            "--checkpoint",
            str(ckpt),
            "--data",
            str(tree),
            "--out",
            str(tmp_path / "sub"),
            "--expected-frames",
            "3",
        ],
    )
    assert again.exit_code == 1 and "--overwrite" in again.output
    wrong = CliRunner().invoke(
        main, ["submit", "--checkpoint", str(ckpt), "--data", str(tree), "--out", str(tmp_path / "sub1000")]
    )
    assert wrong.exit_code == 1 and "KITTI expects 1000" in wrong.output
    assert not (tmp_path / "sub1000").exists() and not (tmp_path / "sub1000.zip").exists()


def test_predict_real_kitti_frame(weights: Path, tmp_path: Path) -> None:
    rgb = SAMPLE / "kitti_raw/2011_09_26/2011_09_26_drive_0035_sync/image_02/data/0000000005.png"
    sparse = SAMPLE / (
        "data_depth_velodyne/train/2011_09_26_drive_0035_sync/proj_depth/velodyne_raw/image_02/0000000005.png"
    )
    image = read_image(rgb)
    sem = np.zeros_like(image)  # stand-in semantic map: sky above, road below
    sem[: image.shape[0] // 2] = (70, 130, 180)
    sem[image.shape[0] // 2 :] = (128, 64, 128)
    write_image(tmp_path / "sem.png", sem)
    run(
        "predict",
        "--checkpoint",
        weights,
        "--rgb",
        rgb,
        "--sparse",
        sparse,
        "--semantic",
        tmp_path / "sem.png",
        "--out",
        tmp_path / "out",
    )
    png = Image.open(tmp_path / "out" / "0000000005.png")
    assert png.size == (1242, 375) and png.mode.startswith("I;16")
    d = read_depth(tmp_path / "out" / "0000000005.png")
    assert (d >= 0).all() and d.max() <= 65535 / 256  # holes (no prediction) stay 0
    again = CliRunner().invoke(
        main,
        [
            "predict",
            "--checkpoint",
            str(weights),
            "--rgb",
            str(rgb),
            "--sparse",
            str(sparse),
            "--semantic",
            str(tmp_path / "sem.png"),
            "--out",
            str(tmp_path / "out"),
        ],
    )
    assert again.exit_code == 1 and "exist" in again.output


def test_python_api_any_size_and_clamping(weights: Path) -> None:
    completer = DepthCompleter.from_pretrained(weights, EngineSpec(device="cpu"))
    rgb = np.random.default_rng(0).integers(0, 255, (50, 77, 3), dtype=np.uint8)
    sparse = np.zeros((50, 77), np.float32)
    sparse[::7, ::5] = 12.5
    res = completer(rgb, sparse, rgb)
    assert res.depth.shape == (50, 77) and set(res.outputs) >= {"color_depth", "refined_depth", "guided_conf"}
    with pytest.raises(ValueError, match="semantic map"):
        completer(rgb, sparse)
    from semattnet.data.io import clamp_for_png

    with pytest.warns(UserWarning, match="1 hole"):  # a hole stays a hole: 0, not 1/256 m
        assert clamp_for_png(np.array([0.0, 5.0])).tolist() == [0.0, 5.0]
    with pytest.warns(UserWarning, match="clamped 1 pixel"):  # a real depth below 1/256 m is raised to it
        assert clamp_for_png(np.array([0.001, 5.0])).min() == pytest.approx(1 / 256)


def test_submission_writer_refuses_and_writes_nothing(tmp_path: Path) -> None:
    expected = {"0000000000.png": (4, 6), "0000000001.png": (4, 6)}
    with pytest.raises(SubmissionError, match="1 predictions for 2 test frames"):
        write_submission_files([("0000000000.png", np.ones((4, 6)))], tmp_path / "s", expected)
    with pytest.raises(SubmissionError, match="prediction is 5x4, the input is 6x4"):
        write_submission_files([("0000000000.png", np.ones((4, 5)))], tmp_path / "s", expected)
    assert list(tmp_path.iterdir()) == []  # no folder, no zip, no temp files
    ok = write_submission_files([(n, np.full((4, 6), 3.0)) for n in expected], tmp_path / "s", expected)
    assert ok.name == "s.zip" and sorted(p.name for p in tmp_path.iterdir()) == ["s", "s.zip"]


def test_error_map_colours() -> None:
    gt = np.array([[10.0, 10.0, 10.0, 0.0]])
    pred = np.array([[10.0, 10.2, 20.0, 5.0]])
    img = error_map(pred, gt)
    assert img[0, 3].tolist() == [0, 0, 0]  # no ground truth
    assert img[0, 0, 2] > img[0, 0, 0]  # perfect: blue
    assert img[0, 2, 0] > img[0, 2, 2]  # 10 m off: red


def test_visualize_command(tree: Path, tmp_path: Path) -> None:
    gt = tree / SEL / "groundtruth_depth"
    out = run("visualize", "--pred", gt, "--gt", gt, "--out", tmp_path / "vis")
    assert "wrote 3 picture(s)" in out
    files = sorted(p.name for p in (tmp_path / "vis").iterdir())
    assert len(files) == 6 and files[0].endswith("_color.png") and files[1].endswith("_error.png")
    err = read_image(tmp_path / "vis" / files[1])
    assert err.shape == (64, 128, 3)
    valid = read_depth(sorted(gt.glob("*.png"))[0]) > 0
    assert (err[valid][:, 2] > err[valid][:, 0]).all()  # perfect prediction: every scored pixel is blue


def test_evaluate_full_val_split(tree: Path, weights: Path, tmp_path: Path) -> None:
    out = run(
        "evaluate",
        "--checkpoint",
        weights,
        "--data",
        tree,
        "--split",
        "val",
        "--out",
        tmp_path / "v",
        "--save-predictions",
        "--workers",
        "0",
        "--batch-size",
        "2",
    )
    assert "RMSE [mm]" in out and "(3 images)" in out
    names = sorted(p.name for p in (tmp_path / "v" / "predictions").glob("*.png"))
    assert names[0] == "2000_01_01_drive_1000_sync_image_02_0000000000.png" and len(names) == 3


def test_submit_takes_weights_and_a_backend(tree: Path, weights: Path, tmp_path: Path) -> None:
    """`submit --weights PATH --backend onnxruntime` gives the same PNGs as `--checkpoint PATH` (torch)."""
    import importlib.util

    backend = "onnxruntime" if importlib.util.find_spec("onnxruntime") else "torch"
    run("submit", "--checkpoint", weights, "--data", tree, "--out", tmp_path / "a", "--expected-frames", "3")
    run(
        "submit",
        "--weights",
        weights,
        "--data",
        tree,
        "--out",
        tmp_path / "b",
        "--expected-frames",
        "3",
        "--backend",
        backend,
    )
    for name in ("0000000000.png", "0000000001.png", "0000000002.png"):
        a, b = read_depth(tmp_path / "a" / name), read_depth(tmp_path / "b" / name)
        assert a.shape == b.shape and float(abs(a - b).max()) <= 2 / 256  # at most a rounding step or two
    both = CliRunner().invoke(
        main,
        [
            "submit",
            "--checkpoint",
            str(weights),
            "--weights",
            str(weights),
            "--data",
            str(tree),
            "--out",
            str(tmp_path / "c"),
        ],
    )
    assert both.exit_code == 2 and "exactly one of --checkpoint or --weights" in both.output
