"""Frame names stay unique, list files are read as untrusted text, and every number an option takes is
bounded: each fault ends in one line naming the inputs or the option (exit 1 or 2), never a traceback, a
silently dropped frame or a replaced input."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import DataError, InputError
from semattnet.cli import main
from semattnet.cli._options import FiniteFloat
from semattnet.data.datasets import get_dataset
from semattnet.data.frames import DuplicateFrameError
from tests.data._datasets import make_void, nyu_frame, write_h5


def run(*args: object) -> tuple[int, str]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    return result.exit_code, result.output


def one_line(output: str) -> str:
    assert "Traceback" not in output and len(output.strip().splitlines()) == 1, output
    return output.strip()


# ---- unique frame names ------------------------------------------------------------------------------------


def test_nyu_scene_and_file_names_that_join_alike_are_refused(tmp_path: Path) -> None:
    pytest.importorskip("h5py")
    rng = np.random.default_rng(0)
    a = write_h5(tmp_path / "train" / "a_b" / "1.h5", nyu_frame(rng, 8, 8))
    b = write_h5(tmp_path / "train" / "a" / "b_1.h5", nyu_frame(rng, 8, 8))
    with pytest.raises(DuplicateFrameError, match="'a_b_1'") as exc:
        get_dataset("nyuv2").source(tmp_path, "train")
    assert str(a) in str(exc.value) and str(b) in str(exc.value) and "\n" not in str(exc.value)


def _void_lists(folder: Path, images: list[str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for role in ("image", "sparse_depth", "ground_truth"):
        (folder / f"test_{role}.txt").write_text("".join(f"{i.replace('image', role)}\n" for i in images))
    return folder


def test_void_images_of_one_sequence_name_under_two_parents_are_refused(tmp_path: Path) -> None:
    lists = _void_lists(tmp_path / "void_1500", ["/x/scene1/image/00000.png", "/y/scene1/image/00000.png"])
    with pytest.raises(DuplicateFrameError, match="'scene1_00000'") as exc:
        get_dataset("void").source(lists, "test")
    assert "/x/scene1/image/00000.png" in str(exc.value) and "/y/scene1/image/00000.png" in str(exc.value)
    code, out = run("predict", "--dataset", "void", "--data", lists, "--method", "classical", "--out", tmp_path / "o")
    assert code == 1 and "both make the frame name 'scene1_00000'" in one_line(out)
    assert not (tmp_path / "o").exists()


def test_folder_frames_with_one_name_are_refused() -> None:
    from semattnet.data.pairing import FramePaths
    from semattnet.data.sources import FolderSource

    frames = [FramePaths("f", Path("a/f.png"), Path("s/f.png")), FramePaths("f", Path("b/f.png"), Path("s/f.png"))]
    with pytest.raises(DuplicateFrameError, match="a/f.png and b/f.png both make the frame name 'f'"):
        FolderSource(frames)


def test_raw_drive_frames_of_one_number_are_refused(tmp_path: Path) -> None:
    from semattnet.data.kitti.raw import RawDrive
    from tests.inference._raw_sample import three_frame_drive

    drive = three_frame_drive(tmp_path)  # frames 5, 6, 7
    image, scan = drive / "image_02" / "data", drive / "velodyne_points" / "data"
    (image / "5.png").write_bytes((image / "0000000005.png").read_bytes())  # frame 5 twice
    (scan / "5.bin").write_bytes((scan / "0000000005.bin").read_bytes())
    with pytest.raises(DuplicateFrameError, match=r"0000000005\.png and 5\.png are both frame 5"):
        RawDrive(drive).names_for("5-6")
    assert len(RawDrive(drive).names_for(None)) == 4  # every frame, by its own name: nothing lost
    (image / "5.png").rename(image / "five.png")
    (scan / "5.bin").rename(scan / "five.bin")
    with pytest.raises(DataError, match=r"five\.png: not a frame number"):
        RawDrive(drive).names_for("5")


# ---- list files ----------------------------------------------------------------------------------------------


def test_empty_void_lists_are_an_error(tmp_path: Path) -> None:
    lists = _void_lists(tmp_path / "void_1500", [])
    code, out = run("predict", "--dataset", "void", "--data", lists, "--method", "classical", "--out", tmp_path / "o")
    expected = f"{lists / 'test_image.txt'}: lists no frames (one path per line expected)"
    assert code == 1 and one_line(out).endswith(expected)


def test_a_void_list_that_is_not_utf8_names_the_list(tmp_path: Path) -> None:
    lists = _void_lists(tmp_path / "void_1500", ["/x/s/image/0.png"])
    (lists / "test_sparse_depth.txt").write_bytes(b"/x/s/sparse_depth/\xff\xfe.png\n")
    code, out = run("data", "check", "--dataset", "void", lists)
    assert code == 1 and f"{lists / 'test_sparse_depth.txt'}: not a UTF-8 text list of paths" in out
    assert "Traceback" not in out
    (lists / "test_sparse_depth.txt").write_bytes(b"/x/s/sparse_depth/\x00.png\n")
    with pytest.raises(DataError, match="test_sparse_depth.txt: line 1 holds a NUL character"):
        get_dataset("void").source(lists, "test")


def test_a_file_a_void_list_names_is_an_input_of_predict(tmp_path: Path) -> None:
    root = make_void(tmp_path / "void", train=0, test=2, h=32, w=48) / "void_1500"
    out = tmp_path / "out"
    args = ("predict", "--dataset", "void", "--data", root, "--method", "classical", "--out", out)
    assert run(*args)[0] == 0
    src = get_dataset("void").source(root, "test")
    assert set(src.listed_files()) <= set(src.inputs()) and len(src.listed_files()) == 2 * 4 + 1  # + one K.txt
    victim = out / f"{src.names[0]}.png"  # the prediction of frame 0 becomes the listed sparse map of frame 0
    sparse_list = root / "test_sparse_depth.txt"
    sparse_list.write_text("\n".join([str(victim), *sparse_list.read_text().splitlines()[1:]]) + "\n")
    before = victim.read_bytes()
    code, output = run(*args, "--overwrite")
    assert code == 1 and f"would replace the input {victim}" in one_line(output)
    assert victim.read_bytes() == before
    sweep = (
        "evaluate",
        "--dataset",
        "void",
        "--data",
        root,
        "--method",
        "classical",
        "--sparsity",
        "keep=1",
        "--out",
        out,
        "--overwrite",
    )
    code, output = run(*sweep)  # evaluate's outputs too: never in a folder holding a listed input
    assert code == 1 and f"output folder {out} holds the input {victim}" in one_line(output)
    assert victim.read_bytes() == before and not (out / "sparsity.json").exists()


# ---- bounds on every number an option takes -----------------------------------------------------------------


def _numeric_options() -> list[tuple[str, click.Parameter]]:
    """Every option of every command (groups walked) whose type is a number."""
    found: list[tuple[str, click.Parameter]] = []

    def walk(cmd: click.Command, path: str) -> None:
        if isinstance(cmd, click.Group):
            for name, sub in cmd.commands.items():
                walk(sub, f"{path} {name}".strip())
            return
        for p in cmd.params:
            if isinstance(p.type, click.IntRange | click.FloatRange | FiniteFloat) or p.type in (
                click.INT,
                click.FLOAT,
            ):
                found.append((path, p))

    walk(main, "")
    return found


def test_every_numeric_option_has_an_upper_bound() -> None:
    options = _numeric_options()
    names = {f"{cmd} {p.opts[0]}" for cmd, p in options}
    expected = {
        "predict --max-skew",
        "predict --speed",
        "predict --max-depth",
        "predict --top-crop",
        "project --scan-period",
        "data bag-from-kitti --nan-points",
        "train --lr",
        "train --width",
        "train --batch-size",
        "train --workers",
        "evaluate --batch-size",
        "evaluate --max-frames",
    }
    assert expected <= names
    for cmd, p in options:
        ctx = click.Context(click.Command(cmd))
        huge = "1e300" if isinstance(p.type, FiniteFloat) else "2000000000"
        with pytest.raises(click.BadParameter):
            p.type.convert(huge, p, ctx)


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (
            [
                "predict",
                "--rgb",
                "{t}",
                "--sparse",
                "{t}",
                "--method",
                "classical",
                "--out",
                "{t}/o",
                "--max-depth",
                "1e300",
            ],
            "--max-depth",
        ),
        (
            ["data", "bag-from-kitti", "--drive", "{t}", "--out", "{t}/b.bag", "--nan-points", "2000000000"],
            "--nan-points",
        ),
        (["train", "--data", "{t}", "--lr", "1e300"], "--lr"),
        (["train", "--data", "{t}", "--width", "1e300"], "--width"),
        (["evaluate", "--data", "{t}", "--method", "classical", "--batch-size", "2000000000"], "--batch-size"),
        (["project", "--points", __file__, "--out", "{t}/x.png", "--scan-period", "1e300"], "--scan-period"),
    ],
)
def test_huge_numbers_are_one_line_naming_the_option(tmp_path: Path, args: list[str], option: str) -> None:
    code, out = run(*(a.format(t=tmp_path) for a in args))
    assert code == 2 and option in out and "Traceback" not in out, out
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_max_skew_is_bounded_in_the_cli_and_the_library(tmp_path: Path) -> None:
    code, out = run(
        "predict",
        "--bag",
        tmp_path,
        "--image-topic",
        "/i",
        "--points-topic",
        "/p",
        "--method",
        "classical",
        "--out",
        tmp_path / "o",
        "--max-skew",
        "1e300",
    )
    assert code == 2 and "--max-skew" in out and "<= 3600" in out and "Traceback" not in out, out
    from semattnet.robotics.bags.pairs import _skew_ns

    for bad in (1e300, float("nan"), -1.0, float("inf")):
        with pytest.raises(InputError, match="max_skew: must be a number of seconds in 0..3600"):
            _skew_ns(bad)
    assert _skew_ns(0.05) == 50_000_000


def test_nan_points_are_bounded_in_the_library(tmp_path: Path) -> None:
    pytest.importorskip("rosbags")
    from semattnet.robotics.bags.sensor_bag import write_sensor_bag

    with pytest.raises(InputError, match="nan_points: must be a whole number in 0..1000000, got 2000000000"):
        write_sensor_bag(tmp_path / "b.mcap", [], None, nan_points=2_000_000_000)  # type: ignore[arg-type]
    assert not (tmp_path / "b.mcap").exists()


def test_segment_with_the_classical_method_is_refused(tmp_path: Path) -> None:
    """``--method classical`` reads no semantic map and runs no engine: --segment, --backend and --amp would
    be ignored unread (a bogus spec or a pickle path passed, and nothing ran)."""
    from tests.inference._raw_sample import DRIVE

    pickle = tmp_path / "model.pkl"
    pickle.write_bytes(b"\x80\x04K\x01.")
    base = ["predict", "--kitti-raw", DRIVE, "--method", "classical", "--out", tmp_path / "o"]
    for extra, option in (
        (["--segment", "bogus:spec"], "--segment"),
        (["--segment", pickle], "--segment"),
        (["--backend", "onnxruntime"], "--backend"),
        (["--amp", "bf16"], "--amp"),
    ):
        code, out = run(*base, *extra)
        assert code == 2 and f"{option} only mean(s) something with --method semattnet" in out, out
    assert not (tmp_path / "o").exists()


# ---- the engine cache is verified, not trusted ---------------------------------------------------------------


def test_a_corrupt_cached_onnx_file_is_rebuilt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnx")
    from PIL import Image

    from tests.inference._raw_sample import tiny_checkpoint

    monkeypatch.setenv("SEMATTNET_CACHE", str(tmp_path / "cache"))
    rng = np.random.default_rng(0)
    Image.fromarray(rng.integers(0, 256, (64, 96, 3), dtype=np.uint8)).save(tmp_path / "rgb.png")
    sparse = np.where(rng.random((64, 96)) < 0.1, rng.uniform(2, 40, (64, 96)), 0)
    Image.fromarray(np.round(sparse * 256).astype(np.uint16)).save(tmp_path / "sparse.png")
    ckpt = tiny_checkpoint(tmp_path / "tiny.safetensors")
    args = (
        "predict",
        "--rgb",
        tmp_path / "rgb.png",
        "--sparse",
        tmp_path / "sparse.png",
        "--weights",
        ckpt,
        "--backend",
        "onnxruntime",
        "--out",
        tmp_path / "out",
        "--overwrite",
    )
    assert run(*args)[0] == 0
    first = (tmp_path / "out" / "rgb.png").read_bytes()
    (cached,) = (tmp_path / "cache" / "engines").glob("*/model.onnx")
    assert cached.with_name("model.onnx.sha256").read_text().strip() != ""
    for damage in ("corrupt", "unrecorded"):
        if damage == "corrupt":
            cached.write_bytes(cached.read_bytes()[:100] + b"\0garbage")
        else:
            cached.with_name("model.onnx.sha256").unlink()  # e.g. a file left by an older release
        code, out = run(*args)
        assert code == 0 and f"{cached}: the cached file" in out and "building it again" in out, out
        assert "Traceback" not in out and (tmp_path / "out" / "rgb.png").read_bytes() == first
        assert cached.with_name("model.onnx.sha256").is_file()
    code, out = run(*args)  # intact now: used as it is, no line
    assert code == 0 and "building it again" not in out
