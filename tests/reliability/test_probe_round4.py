"""Issue 27, round 4: the classes of fault an independent hostile probe found, each over several variants.

Special files (FIFOs, devices) wherever a file is read; corrupt OXTS packets blamed on the OXTS file; the
checkpoint named in "not a SemAttNet state dict"; PCD headers that contradict themselves; options that
would be ignored; depths a KITTI PNG cannot hold; meaningless intrinsics and colours in the Python API;
a ``--mirror`` that is not a URL. Each: one line naming the file or option, nothing changed."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from semattnet._errors import DataError, InputError, SemAttNetError
from semattnet.cli import main
from semattnet.inference.backends import EngineSpec
from tests._helpers import SAMPLE

RIG = {
    "K": [[50, 0, 16], [0, 50, 12], [0, 0, 1]],
    "T_cam_lidar": [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
    "image_size": [32, 24],
}
T16 = "0,-1,0,0,0,0,-1,0,1,0,0,0,0,0,0,1"
DRIVE = ("2011_09_26", "2011_09_26_drive_0035_sync")


@pytest.fixture(autouse=True)
def _no_hang() -> Iterator[None]:
    """A reader that opened a FIFO would block forever: fail the test after 20 s instead."""

    def fail(*_: object) -> None:
        raise TimeoutError("blocked: a special file was opened")

    old = signal.signal(signal.SIGALRM, fail)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def _hashes(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file() and not p.is_symlink()
    }


def _cli(root: Path, *args: object) -> tuple[int, str]:
    """Run the CLI; assert no traceback, one message line and every file under ``root`` unchanged."""
    before = _hashes(root)
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    err = [x for x in res.output.splitlines() if x.strip() and not x.startswith(("Usage: ", "Try '"))]
    assert "Traceback" not in res.output and len(err) == 1, res.output
    assert _hashes(root) == before
    return res.exit_code, err[0]


def _one_line(fn: Callable[[], object], cls: type[Exception] = SemAttNetError) -> str:
    with pytest.raises(cls) as err:
        fn()
    assert "\n" not in str(err.value)
    return str(err.value)


def _rig(tmp_path: Path) -> Path:
    (tmp_path / "rig.json").write_text(json.dumps(RIG))
    return tmp_path / "rig.json"


def _scan(tmp_path: Path, pts: list[list[float]] | None = None) -> Path:
    np.save(tmp_path / "scan.npy", np.array(pts or [[5.0, 0, 0], [6.0, 0.5, 0.2]], np.float32))
    return tmp_path / "scan.npy"


# ----------------------------------------------------------------------------- special files


def _special(path: Path, kind: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        path.symlink_to("/dev/zero")
    else:
        path.mkdir()
    return path


def _readers() -> dict[str, Callable[[Path], object]]:
    from semattnet.data.io import read_depth, read_image
    from semattnet.geometry import read_oxts_motion, read_points, read_rig_json
    from semattnet.geometry.calibration import read_cam_to_cam
    from semattnet.training.config import TrainConfig
    from semattnet.weights import load_checkpoint

    return {
        "a.png": read_image,
        "d.png": read_depth,
        "s.bin": read_points,
        "rig.json": read_rig_json,
        "calib_cam_to_cam.txt": read_cam_to_cam,
        "oxts.txt": read_oxts_motion,
        "w.pt": load_checkpoint,
        "config.json": TrainConfig.load,
    }


@pytest.mark.parametrize("kind", ["fifo", "device", "folder"])
@pytest.mark.parametrize("name", sorted(_readers()))
def test_every_reader_refuses_special_files_without_opening_them(tmp_path: Path, name: str, kind: str) -> None:
    path = _special(tmp_path / name, kind)
    msg = _one_line(lambda: _readers()[name](path))
    assert str(path) in msg and ("a FIFO" in msg or "device" in msg or "folder" in msg), msg


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_cli_inputs_that_are_special_files(tmp_path: Path, kind: str) -> None:
    from semattnet.data.io import write_depth

    _special(tmp_path / "cfg.json", kind)
    code, msg = _cli(tmp_path, "train", "--data", tmp_path, "--config", tmp_path / "cfg.json", "--out", tmp_path / "r")
    assert code == 1 and "cfg.json" in msg, msg
    write_depth(tmp_path / "pred" / "a.png", np.full((4, 6), 5.0))
    _special(tmp_path / "gt" / "a.png", kind)
    code, msg = _cli(tmp_path, "metrics", tmp_path / "pred", tmp_path / "gt")
    assert code == 1 and "gt/a.png" in msg, msg


# ----------------------------------------------------------------------------- OXTS packets


def _oxts(path: Path, index: int, value: str) -> Path:
    vals = ["0.1"] * 30
    vals[index] = value
    path.write_text(" ".join(vals) + "\n")
    return path


BAD_OXTS = [(8, "nan"), (9, "inf"), (10, "-inf"), (8, "1e300"), (22, "nan"), (22, "1e6")]


@pytest.mark.parametrize(("index", "value"), BAD_OXTS)
def test_a_corrupt_oxts_packet_is_blamed_on_the_oxts_file(tmp_path: Path, index: int, value: str) -> None:
    from semattnet.geometry import read_oxts_motion

    path = _oxts(tmp_path / "oxts.txt", index, value)
    assert "oxts.txt: OXTS velocity" in _one_line(lambda: read_oxts_motion(path), DataError)
    code, msg = _cli(
        tmp_path,
        "project",
        "--points",
        _scan(tmp_path),
        "--rig",
        _rig(tmp_path),
        "--deskew-oxts",
        path,
        "--out",
        tmp_path / "o.png",
    )
    assert code == 1 and "oxts.txt" in msg and "scan.npy" not in msg, msg
    assert not (tmp_path / "o.png").exists()


def test_a_raw_drive_with_a_corrupt_oxts_packet_names_it(tmp_path: Path) -> None:
    shutil.copytree(SAMPLE / "kitti_raw", tmp_path / "raw")
    drive = tmp_path / "raw" / DRIVE[0] / DRIVE[1]
    packet = drive / "oxts" / "data" / "0000000005.txt"
    vals = packet.read_text().split()
    vals[8] = "nan"
    packet.write_text(" ".join(vals) + "\n")
    code, msg = _cli(
        tmp_path, "predict", "--method", "classical", "--kitti-raw", drive, "--deskew", "--out", tmp_path / "o"
    )
    assert code == 1 and "0000000005.txt" in msg and "OXTS" in msg, msg


@pytest.mark.parametrize(
    ("velocity", "yaw", "period"),
    [
        ([np.nan, 0, 0], 0.0, 0.1),
        ([0, 0], 0.0, 0.1),
        ([0, 0, 0], np.inf, 0.1),
        ([0, 0, 0], 0.0, 0.0),
        ([0, 0, 0], 0.0, np.nan),
    ],
)
def test_deskew_refuses_meaningless_motion(velocity: list[float], yaw: float, period: float) -> None:
    from semattnet.geometry import deskew_scan

    assert "deskew_scan" in _one_line(lambda: deskew_scan(np.ones((3, 4)), np.array(velocity), yaw, period), InputError)


# ----------------------------------------------------------------------------- the checkpoint named


@pytest.mark.parametrize("fmt", ["pt", "safetensors", "pth.tar"])
def test_not_a_semattnet_state_dict_names_the_file(tmp_path: Path, fmt: str) -> None:
    from safetensors.torch import save_file

    import semattnet

    path = tmp_path / f"other.{fmt}"
    sd = {"conv.weight": torch.zeros(2, 2, 3, 3)}
    save_file(sd, str(path)) if fmt == "safetensors" else torch.save({"state_dict": sd}, path)
    msg = _one_line(lambda: semattnet.from_pretrained(path, progress=False))
    assert str(path) in msg and "not a SemAttNet state dict" in msg, msg
    code, msg = _cli(tmp_path, "convert", path, tmp_path / "o.safetensors")
    assert code == 1 and str(path) in msg, msg


# ----------------------------------------------------------------------------- PCD headers


@pytest.mark.parametrize(("width", "height"), [("99999999", "99999999"), ("2", "1"), ("0", "1"), ("x", "1")])
def test_pcd_width_times_height_must_be_points(tmp_path: Path, width: str, height: str) -> None:
    from semattnet.geometry import read_points

    path = tmp_path / "c.pcd"
    path.write_text(
        f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {width}\nHEIGHT {height}\n"
        "POINTS 1\nDATA ascii\n5 0 0\n"
    )
    assert "c.pcd: PCD WIDTH" in _one_line(lambda: read_points(path), DataError)


# ----------------------------------------------------------------------------- options that would be ignored


def _tree(tmp_path: Path) -> None:
    from semattnet.data.io import write_depth, write_image

    write_image(tmp_path / "rgb" / "a.png", np.zeros((8, 12, 3), np.uint8))
    sparse = np.zeros((8, 12))
    sparse[4, 6] = 5.0
    write_depth(tmp_path / "sparse" / "a.png", sparse)


@pytest.mark.parametrize(
    ("extra", "named", "why"),
    [
        (["--camera", "3"], "--camera", "is an option of --kitti-raw"),
        (["--K", "kitti"], "--K", "only mean"),
        (["--K", "50,50,6,4"], "--K", "only mean"),
    ],
)
def test_predict_refuses_options_it_would_ignore(tmp_path: Path, extra: list[str], named: str, why: str) -> None:
    _tree(tmp_path)
    code, msg = _cli(
        tmp_path,
        "predict",
        "--method",
        "classical",
        "--rgb",
        tmp_path / "rgb",
        "--sparse",
        tmp_path / "sparse",
        "--out",
        tmp_path / "o",
        *extra,
    )
    assert code == 2 and named in msg and why in msg and not (tmp_path / "o").exists(), msg


@pytest.mark.parametrize(
    ("extra", "named"), [(["--scan-period", "0.2"], "--scan-period"), (["--camera", "3"], "--camera")]
)
def test_project_refuses_options_it_would_ignore(tmp_path: Path, extra: list[str], named: str) -> None:
    code, msg = _cli(
        tmp_path, "project", "--points", _scan(tmp_path), "--rig", _rig(tmp_path), "--out", tmp_path / "o.png", *extra
    )
    assert code == 2 and named in msg and not (tmp_path / "o.png").exists(), msg


@pytest.mark.parametrize(("args", "named"), [(["--T", ",".join(["1"] * 15)], "--T"), (["--K", "1,2,3"], "--K")])
def test_project_number_options_are_named(tmp_path: Path, args: list[str], named: str) -> None:
    base = {"--K": "50,50,16,12", "--T": T16}
    base[args[0]] = args[1]
    code, msg = _cli(
        tmp_path,
        "project",
        "--points",
        _scan(tmp_path),
        "--K",
        base["--K"],
        "--T",
        base["--T"],
        "--size",
        "32x24",
        "--out",
        tmp_path / "o.png",
    )
    assert code == 1 and msg.split(": ")[1].startswith(named), msg


@pytest.mark.parametrize("frames", ["0-5,abc", "-1", "3-1"])
def test_frame_specs_name_the_option(frames: str) -> None:
    from semattnet.data.kitti_raw import parse_frames

    assert "--frames" in _one_line(lambda: parse_frames(frames), DataError)


# ----------------------------------------------------------------------------- depths a PNG cannot hold


@pytest.mark.parametrize("value", [300.0, 1e6, -1.0, np.nan, np.inf])
def test_write_depth_refuses_what_a_kitti_png_cannot_hold(tmp_path: Path, value: float) -> None:
    from semattnet.data.io import write_depth

    depth = np.full((4, 4), 5.0)
    depth[1, 2] = value
    assert "a.png: depth to write" in _one_line(lambda: write_depth(tmp_path / "a.png", depth), DataError)
    assert not (tmp_path / "a.png").exists()
    write_depth(tmp_path / "ok.png", np.full((4, 4), 65535 / 256))  # the top of the range still writes


@pytest.mark.parametrize("depth_m", [256.5, 1000.0, 1e5])
def test_project_refuses_points_deeper_than_a_png_holds(tmp_path: Path, depth_m: float) -> None:
    code, msg = _cli(
        tmp_path,
        "project",
        "--points",
        _scan(tmp_path, [[depth_m, 0, 0], [6.0, 0.5, 0.2]]),
        "--rig",
        _rig(tmp_path),
        "--out",
        tmp_path / "o.png",
    )
    assert code == 1 and "scan.npy" in msg and "deeper than" in msg and not (tmp_path / "o.png").exists(), msg


# ----------------------------------------------------------------------------- the Python API


BAD_K = [np.zeros((3, 3)), np.diag([np.nan, 1.0, 1.0]), np.diag([-50.0, 50.0, 1.0]), np.eye(4)]


@pytest.mark.parametrize("K", BAD_K, ids=["zero", "nan", "negative", "4x4"])
def test_geometry_api_refuses_meaningless_intrinsics(K: np.ndarray) -> None:
    from semattnet.geometry import depth_to_points, project_points

    msg = _one_line(lambda: project_points(np.array([[0.0, 0, 5.0]]), K, np.eye(4), (32, 24)), InputError)
    assert "project_points: K" in msg
    assert "depth_to_points: K" in _one_line(lambda: depth_to_points(np.ones((4, 4)), K), InputError)


def test_depth_to_points_refuses_non_finite_depth() -> None:
    from semattnet.geometry import depth_to_points

    K = np.array([[50, 0, 2], [0, 50, 2], [0, 0, 1.0]])
    assert "NaN" in _one_line(lambda: depth_to_points(np.full((4, 4), np.nan), K), InputError)


@pytest.fixture(scope="module")
def completer():  # type: ignore[no-untyped-def]
    import semattnet

    torch.manual_seed(0)
    return semattnet.DepthCompleter(semattnet.build_model("semattnet", width=0.125).eval(), EngineSpec(device="cpu"))


@pytest.mark.parametrize(
    ("which", "value"), [("semantic", 1e9), ("semantic", -1.0), ("rgb", 256.0), ("rgb", -5.0), ("semantic", np.inf)]
)
def test_depth_completer_refuses_colours_outside_0_255(completer, which: str, value: float) -> None:  # type: ignore[no-untyped-def]
    frame = {"rgb": np.zeros((16, 16, 3)), "semantic": np.zeros((16, 16, 3))}
    frame[which][2, 3, 1] = value
    sparse = np.zeros((16, 16), np.float32)
    sparse[3, 3] = 5.0
    msg = _one_line(lambda: completer(frame["rgb"], sparse, frame["semantic"]), InputError)
    assert msg.startswith(which), msg


# ----------------------------------------------------------------------------- data download --mirror


@pytest.mark.parametrize("mirror", ["not a url", "/some/folder", "ftp://host/x", ""])
def test_a_mirror_that_is_not_a_url_is_refused_first(tmp_path: Path, mirror: str) -> None:
    from semattnet.data.download import download_dataset

    msg = _one_line(lambda: download_dataset("void", tmp_path / "o", accept_license=True, mirror=mirror), InputError)
    assert "--mirror" in msg and not (tmp_path / "o").exists()
    code, msg = _cli(
        tmp_path,
        "data",
        "download",
        "--dataset",
        "void",
        "--accept-license",
        "--mirror",
        mirror,
        "--out",
        tmp_path / "o",
        "--cache-dir",
        tmp_path / "cache",
    )
    assert code == 1 and "--mirror" in msg and not (tmp_path / "o").exists(), msg


@pytest.mark.parametrize("kind", ["fifo", "device", "folder"])
def test_a_pretrained_folder_with_a_special_config_is_refused(tmp_path: Path, kind: str) -> None:
    import semattnet
    from tests.inference._raw_sample import tiny_checkpoint

    tiny_checkpoint(tmp_path / "pre" / "model.safetensors")
    _special(tmp_path / "pre" / "config.json", kind)
    msg = _one_line(lambda: semattnet.from_pretrained(tmp_path / "pre"))
    assert "config.json" in msg and "not a regular" in msg, msg


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_a_file_url_of_a_special_file_is_refused(tmp_path: Path, kind: str) -> None:
    from semattnet.weights import fetch

    src = _special(tmp_path / "remote.bin", kind)
    assert "not a regular" in _one_line(lambda: fetch(src.as_uri(), cache_dir=tmp_path / "cache", progress=False))
    assert not [p for p in (tmp_path / "cache").rglob("*.part")]


# ----------------------------------------------------------------------------- outputs


@pytest.mark.parametrize("kind", ["fifo", "hardlink-into-gt"])
def test_metrics_json_never_replaces_a_special_file_or_an_input(tmp_path: Path, kind: str) -> None:
    from semattnet.data.io import write_depth

    for d in ("pred", "gt"):
        write_depth(tmp_path / d / "a.png", np.full((4, 6), 5.0))
    json_path = tmp_path / "m.json"
    os.mkfifo(json_path) if kind == "fifo" else os.link(tmp_path / "gt" / "a.png", json_path)
    code, msg = _cli(tmp_path, "metrics", tmp_path / "pred", tmp_path / "gt", "--json", json_path, "--overwrite")
    assert code == 1 and "m.json" in msg, msg
    assert json_path.is_fifo() if kind == "fifo" else json_path.stat().st_nlink == 2


def test_visualize_never_replaces_a_hard_link_to_its_ground_truth(tmp_path: Path) -> None:
    from semattnet.data.io import write_depth

    for d in ("pred", "gt"):
        write_depth(tmp_path / d / "a.png", np.full((4, 6), 5.0))
    (tmp_path / "o").mkdir()
    os.link(tmp_path / "gt" / "a.png", tmp_path / "o" / "a_color.png")
    code, msg = _cli(
        tmp_path,
        "visualize",
        "--pred",
        tmp_path / "pred",
        "--gt",
        tmp_path / "gt",
        "--out",
        tmp_path / "o",
        "--overwrite",
    )
    assert code == 1 and "would replace the input" in msg and (tmp_path / "o" / "a_color.png").stat().st_nlink == 2


@pytest.mark.parametrize("where", ["data", "data/run", "semantic"])
def test_train_never_writes_its_run_into_the_data(tmp_path: Path, where: str) -> None:
    from semattnet.training.config import TrainConfig
    from semattnet.training.trainer import train

    for d in ("data", "semantic"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "keep.txt").write_text(d)
    cfg = TrainConfig(data=str(tmp_path / "data"), semantic_root=str(tmp_path / "semantic"), out=str(tmp_path / where))
    assert "input folder" in _one_line(lambda: train(cfg, overwrite=True))
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == ["keep.txt"]


def _void_zip(path: Path, write: Callable[[zipfile.ZipFile], None]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        write(zf)
    return path


def _link(zf: zipfile.ZipFile) -> None:
    info = zipfile.ZipInfo("void/lnk")
    info.external_attr, info.create_system = 0o120777 << 16, 3
    zf.writestr(info, "/etc/passwd")


def _twice(zf: zipfile.ZipFile) -> None:
    zf.writestr("void/a.txt", "1")
    with pytest.warns(UserWarning, match="Duplicate"):
        zf.writestr("void/a.txt", "22")


def _bomb(zf: zipfile.ZipFile) -> None:
    with zf.open("void/bomb.bin", "w") as f:
        for _ in range(72):  # 72 MiB of zeros in ~70 KiB
            f.write(bytes(1 << 20))


@pytest.mark.parametrize("write", [_link, _twice, _bomb], ids=["symlink", "duplicate", "bomb"])
def test_hostile_dataset_archives_unpack_nothing(tmp_path: Path, write: Callable[[zipfile.ZipFile], None]) -> None:
    from semattnet.data.download import UnsafeArchiveError, extract_zip

    archive = _void_zip(tmp_path / "a.zip", write)
    msg = _one_line(lambda: extract_zip(archive, tmp_path / "dest"), UnsafeArchiveError)
    assert "a.zip" in msg and "nothing unpacked" in msg
    assert not [p for p in (tmp_path / "dest").rglob("*") if p.is_file()]
