"""The one frame loop: every source through one writer, one hole / clamp rule, checks before the model loads."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.baselines import ClassicalCompleter
from semattnet.data.io import MAX_DEPTH_M, read_depth, write_depth, write_image
from semattnet.data.kitti.raw import RawDrive
from semattnet.data.sources import FolderSource, KittiSplitSource, RawDriveSource
from semattnet.inference import Completion, check_frames, complete_frames
from semattnet.inference.sinks import DepthPngSink, OutputSettings, default_sinks, predict_frame
from semattnet.synthetic.tree import write_synthetic_kitti
from tests.inference._raw_sample import DRIVE


class _Bad(ClassicalCompleter):
    """Returns a fixed depth with NaN, negative, zero, too-small and too-large values, whatever the input."""

    def __call__(self, rgb, sparse, semantic=None):  # type: ignore[no-untyped-def]
        d = np.full(sparse.shape, 7.3, np.float32)
        d[0, :10] = np.nan
        d[1, :7] = -2.0
        d[2, :5] = 0.0
        d[3, :3] = 1e-4
        d[4, :2] = 1e4
        return Completion(d)


def _run(source, out: Path) -> list[str]:  # type: ignore[no-untyped-def]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_frames(source, default_sinks(OutputSettings(npy=True)), out).run(_Bad(), log=lambda s: None)
    return sorted(str(w.message) for w in caught)


def test_raw_and_folder_sources_write_bad_depths_alike(tmp_path: Path) -> None:
    frame = next(RawDrive(DRIVE).select("5"))
    write_image(tmp_path / "rgb" / "0000000005.png", frame.image)
    write_depth(tmp_path / "sparse" / "0000000005.png", RawDriveSource(DRIVE, "5").load("0000000005").sparse)
    raw = _run(RawDriveSource(DRIVE, "5"), tmp_path / "raw")
    folder = _run(FolderSource.pair(tmp_path / "rgb", tmp_path / "sparse"), tmp_path / "folder")
    assert raw == folder and any("0000000005: 22 hole(s)" in m for m in raw)  # 10 NaN + 7 negative + 5 zero
    assert any("clamped 3 pixel(s) below" in m and "2 above" in m for m in raw)
    for name in ("0000000005.png", "0000000005_color.png"):
        assert (tmp_path / "raw" / name).read_bytes() == (tmp_path / "folder" / name).read_bytes()
    d = read_depth(tmp_path / "raw" / "0000000005.png")
    assert (d[:3, :10][[0] * 10 + [1] * 7 + [2] * 5, list(range(10)) + list(range(7)) + list(range(5))] == 0).all()
    assert (
        d[3, 0] == pytest.approx(1 / 256)
        and d[4, 0] == pytest.approx(MAX_DEPTH_M)
        and d[5, 5] == pytest.approx(7.3, abs=2e-3)
    )
    npy = np.load(tmp_path / "raw" / "0000000005.npy")
    assert np.isfinite(npy).all() and npy[1, 0] == 0 and npy[5, 5] == pytest.approx(7.3)  # clamped, unquantised


def test_quantised_once_and_stored_depth_shared() -> None:
    frame = RawDriveSource(DRIVE, "5").load("0000000005")
    pred = predict_frame(frame, _Bad()(frame.rgb, frame.sparse))
    assert pred.png.dtype == np.uint16 and np.array_equal(pred.stored * 256, pred.png.astype(np.float32))
    assert pred.cloud(80.0, 0) is pred.cloud(80.0, 0)  # the PLY and the panel share one cloud of the stored depth


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("kitti")
    write_synthetic_kitti(root, 2, (64, 96), seed=3, eval_frames=2, workers=1)
    return root


def test_every_source_goes_through_the_one_writer(tree: Path, tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    written: list[str] = []
    save = DepthPngSink.save
    monkeypatch.setattr(
        DepthPngSink, "save", lambda self, path, pred: (written.append(path.name), save(self, path, pred))
    )
    split = KittiSplitSource(tree, "val_select")
    paths = check_frames(split, default_sinks(), tmp_path / "split").run(ClassicalCompleter(), log=lambda s: None).paths
    assert [p.name for p in paths] == [f"{n}.png" for n in split.names] == written
    frame = split.load(split.names[0])
    assert frame.gt is not None and frame.K is not None and "gt" in frame.paths
    assert np.array_equal(
        read_depth(paths[0]), predict_frame(frame, ClassicalCompleter()(frame.rgb, frame.sparse)).stored
    )
    written.clear()
    complete_frames(RawDriveSource(DRIVE, "5"), ClassicalCompleter(), default_sinks(), tmp_path / "raw")
    assert written == ["0000000005.png"]
    written.clear()
    from semattnet.cli import main

    result = CliRunner().invoke(
        main,
        [
            "evaluate",
            "--checkpoint",
            str(_tiny(tmp_path)),
            "--data",
            str(tree),
            "--out",
            str(tmp_path / "ev"),
            "--save-predictions",
            "--workers",
            "0",
        ],
    )
    assert result.exit_code == 0, result.output
    assert sorted(written) == sorted(p.name for p in (tmp_path / "ev" / "predictions").glob("*.png")) and written


def _tiny(tmp_path: Path) -> Path:
    from tests.inference._raw_sample import tiny_checkpoint

    return tiny_checkpoint(tmp_path / "tiny.safetensors")


def _no_model(*args, **kwargs):  # type: ignore[no-untyped-def]
    raise AssertionError("the model was loaded")


@pytest.mark.parametrize("case", ["existing", "corrupt"])
def test_predict_checks_everything_before_loading_the_model(tmp_path: Path, monkeypatch, case: str) -> None:  # type: ignore[no-untyped-def]
    import semattnet.inference.completer as completer
    from semattnet.cli import main

    monkeypatch.setattr(completer, "load_completer", _no_model)
    for name in ("a.png", "b.png"):
        write_image(tmp_path / "rgb" / name, np.zeros((8, 12, 3), np.uint8))
        write_depth(tmp_path / "sparse" / name, np.ones((8, 12)))
    out = tmp_path / "out"
    if case == "existing":
        write_image(out / "b_color.png", np.zeros((2, 2, 3), np.uint8))
    else:
        (tmp_path / "sparse" / "b.png").write_bytes(b"not a png")
    weights = tmp_path / "never-read.safetensors"  # exists (the option checks that), never loaded
    weights.write_bytes(b"x")
    args = [
        "predict",
        "--weights",
        weights,
        "--rgb",
        tmp_path / "rgb",
        "--sparse",
        tmp_path / "sparse",
        "--out",
        out,
        "--on-error",
        "stop",  # the default (skip) would skip the corrupt frame and load the model
    ]
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 1 and "the model was loaded" not in result.output, result.output
    assert ("b_color.png exists" if case == "existing" else "b.png") in result.output
    assert not (out / "a.png").exists()


def test_evaluate_checks_before_loading_the_model(tree: Path, tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import semattnet.inference.completer as completer
    from semattnet.cli import main

    monkeypatch.setattr(completer, "load_completer", _no_model)
    (tmp_path / "ev").mkdir()
    (tmp_path / "ev" / "old.txt").write_text("x")
    weights = tmp_path / "never-read.safetensors"  # exists (the option checks that), never loaded
    weights.write_bytes(b"x")
    result = CliRunner().invoke(
        main,
        ["evaluate", "--weights", str(weights), "--data", str(tree), "--out", str(tmp_path / "ev"), "--workers", "0"],
    )
    assert result.exit_code == 1 and "not empty" in result.output and "the model was loaded" not in result.output
    result = CliRunner().invoke(
        main, ["evaluate", "--weights", str(weights), "--data", str(tmp_path), "--workers", "0"]
    )
    assert result.exit_code == 1 and "no val_select frames" in result.output, result.output
