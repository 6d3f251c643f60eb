"""``--precision f32|bf16|int8`` and ``--calibration`` on ``predict``: the rules (usage errors before any work) and
int8 end to end on OpenVINO + NNCF, calibrated on the user's own frames."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import read_depth, write_depth, write_image


@pytest.fixture
def frames(tmp_path: Path) -> list[str]:
    rng = np.random.default_rng(0)
    for d in ("rgb", "sparse", "semantic"):
        (tmp_path / d).mkdir()
    for i in range(2):
        write_image(tmp_path / "rgb" / f"f{i}.png", rng.integers(0, 256, (64, 96, 3), dtype=np.uint8))
        write_image(tmp_path / "semantic" / f"f{i}.png", np.full((64, 96, 3), (128, 64, 128), np.uint8))
        depth = np.where(rng.random((64, 96)) < 0.1, rng.uniform(1, 50, (64, 96)), 0).astype(np.float32)
        write_depth(tmp_path / "sparse" / f"f{i}.png", depth)
    return [f"--{d}={tmp_path / d}" for d in ("rgb", "sparse", "semantic")]


def _predict(*args: str) -> object:
    return CliRunner().invoke(main, ["predict", *args])


@pytest.mark.parametrize(
    ("options", "words"),
    [
        (
            ["--precision", "int8"],
            "--precision: the torch backend runs f32, bf16, fp16, not 'int8'; int8 runs on the openvino backend",
        ),
        (["--precision", "int8", "--backend", "onnxruntime"], "the onnxruntime backend runs f32, not 'int8'"),
        (["--calibration", "{rgb}"], "--calibration only mean(s) something with --precision int8"),
        (["--precision", "bf16", "--amp", "fp16"], "--precision 'bf16' and --amp 'fp16' disagree"),
        (["--precision", "f32", "--method", "classical"], "--method classical runs none"),
    ],
)
def test_rules(frames: list[str], tmp_path: Path, options: list[str], words: str) -> None:
    options = [o.format(rgb=tmp_path / "rgb") for o in options]
    model = [] if "classical" in options else ["--weights", "semattnet-demo-ref-seed0"]
    res = _predict(*frames, *model, *options, "--out", str(tmp_path / "out"))
    assert res.exit_code == 2 and words in res.output, res.output  # type: ignore[attr-defined]
    assert not (tmp_path / "out").exists()


def test_bf16_on_the_torch_backend_is_autocast(frames: list[str], tmp_path: Path) -> None:
    for precision in ("f32", "bf16"):
        res = _predict(
            *frames,
            "--weights",
            "semattnet-demo-ref-seed0",
            "--precision",
            precision,
            "--out",
            str(tmp_path / precision),
        )
        assert res.exit_code == 0, res.output  # type: ignore[attr-defined]
    a, b = (read_depth(tmp_path / p / "f0.png") for p in ("f32", "bf16"))
    assert 0 < np.abs(a - b).max() < 0.1 * a.max()  # bfloat16 arithmetic: close, not equal


needs_int8 = pytest.mark.skipif(
    importlib.util.find_spec("openvino") is None or importlib.util.find_spec("nncf") is None,
    reason="needs openvino and nncf (pip install 'semattnet[openvino]')",
)


@needs_int8
@pytest.mark.slow  # ONNX export, OpenVINO conversion and NNCF calibration: about a minute on 2 cores
def test_int8_on_openvino_calibrated_on_own_frames(frames: list[str], tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setenv("SEMATTNET_CACHE", str(tmp_path / "cache"))
    common = [*frames, "--weights", "semattnet-demo-ref-seed0", "--backend", "openvino"]
    res = _predict(*common, "--out", str(tmp_path / "f32"))
    assert res.exit_code == 0, res.output  # type: ignore[attr-defined]
    res = _predict(*common, "--precision", "int8", "--calibration", str(tmp_path), "--out", str(tmp_path / "int8"))
    assert res.exit_code == 0, res.output  # type: ignore[attr-defined]
    a, b = (read_depth(tmp_path / p / "f0.png") for p in ("f32", "int8"))
    valid = a > 0
    assert 0 < np.abs(a - b)[valid].mean() < 0.05 * a[valid].mean()  # quantised: close on average, not equal
    assert list((tmp_path / "cache").rglob("int8-*")), "the quantised IR is cached"
