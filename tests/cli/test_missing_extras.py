"""Every optional feature without its package: one line naming the ``pip install 'semattnet[EXTRA]'`` to run,
exit status 1, no traceback. Each package is hidden from the import system for the test (``sys.modules[NAME] =
None`` makes ``import NAME`` raise), so the test runs whether or not the package is installed."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import write_depth, write_image


def _hide(monkeypatch: pytest.MonkeyPatch, *modules: str) -> None:
    for name in modules:
        for key in [k for k in sys.modules if k == name or k.startswith(name + ".")] + [name]:
            monkeypatch.setitem(sys.modules, key, None)


@pytest.fixture
def frames(tmp_path: Path) -> list[str]:
    """One 32x64 frame: --rgb, --sparse, --semantic."""
    rng = np.random.default_rng(0)
    for d in ("rgb", "sparse", "semantic"):
        (tmp_path / d).mkdir()
    write_image(tmp_path / "rgb" / "f.png", rng.integers(0, 256, (32, 64, 3), dtype=np.uint8))
    write_image(tmp_path / "semantic" / "f.png", np.full((32, 64, 3), (128, 64, 128), np.uint8))
    depth = np.where(rng.random((32, 64)) < 0.1, rng.uniform(1, 50, (32, 64)), 0).astype(np.float32)
    write_depth(tmp_path / "sparse" / "f.png", depth)
    return [f"--{d}={tmp_path / d}" for d in ("rgb", "sparse", "semantic")]


def _one_line(args: list[str], extra: str, package: str) -> None:
    res = CliRunner().invoke(main, args)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output and "a bug in semattnet" not in res.output, res.output
    assert lines[-1].startswith("Error: ") and f"'{package}': pip install 'semattnet[{extra}]'" in lines[-1], lines


@pytest.mark.parametrize(
    ("hidden", "weights", "package"),
    [
        (("huggingface_hub",), "hf://owner/repo", "huggingface_hub"),
        (("gdown",), "gdrive://abcdefghijklmnop", "gdown"),
        (("huggingface_hub", "pooch"), "http://127.0.0.1:9/w.safetensors", "pooch"),
    ],
)
def test_hub(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, hidden: tuple[str, ...], weights: str, package: str
) -> None:
    monkeypatch.setenv("SEMATTNET_CACHE", str(tmp_path / "cache"))
    _hide(monkeypatch, *hidden)
    _one_line(["info", "--weights", weights], "hub", package)


@pytest.mark.parametrize(
    ("backend", "module", "extra"), [("onnxruntime", "onnxruntime", "onnx"), ("openvino", "openvino", "openvino")]
)
def test_engines(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, frames: list[str], backend: str, module: str, extra: str
) -> None:
    _hide(monkeypatch, module)
    args = ["predict", *frames, "--weights", "semattnet-demo-ref-seed0", "--backend", backend]
    _one_line([*args, "--out", str(tmp_path / "out")], extra, module)
    assert not (tmp_path / "out").exists()


def test_segmenter(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, frames: list[str]) -> None:
    _hide(monkeypatch, "transformers")
    _one_line(
        ["segment", "--model", "hf:default", "--images", frames[0].split("=", 1)[1], "--out", str(tmp_path / "maps")],
        "segment",
        "transformers",
    )


@pytest.mark.parametrize(
    ("option", "module", "extra", "package"),
    [
        (["--rerun", "rec.rrd"], "rerun", "rerun", "rerun-sdk"),
        (["--live", "127.0.0.1:0"], "foxglove", "live", "foxglove-sdk"),
    ],
)
def test_run_outputs(
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    frames: list[str],
    option: list[str],
    module: str,
    extra: str,
    package: str,
) -> None:
    _hide(monkeypatch, module)
    option = [o if not o.endswith(".rrd") else str(tmp_path / o) for o in option]
    args = ["predict", *frames, "--method", "classical", "--K", "50,50,32,16", *option]
    _one_line([*args, "--out", str(tmp_path / "out")], extra, package)


def test_bags(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _hide(monkeypatch, "rosbags")
    bag = tmp_path / "in.bag"
    bag.write_bytes(b"#ROSBAG V2.0\n")
    topics = ["--image-topic", "/cam", "--points-topic", "/lidar"]
    _one_line(
        ["predict", "--bag", str(bag), *topics, "--method", "classical", "--out", str(tmp_path / "out")],
        "ros",
        "rosbags",
    )


def test_nyu(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _hide(monkeypatch, "h5py")
    (tmp_path / "nyudepthv2" / "val" / "official").mkdir(parents=True)
    (tmp_path / "nyudepthv2" / "val" / "official" / "00001.h5").write_bytes(b"\x89HDF\r\n\x1a\n")
    res = CliRunner().invoke(main, ["data", "check", "--dataset", "nyuv2", str(tmp_path / "nyudepthv2")])
    assert "Traceback" not in res.output and res.exit_code == 1, res.output
    assert "'h5py': pip install 'semattnet[nyu]'" in res.output, res.output
