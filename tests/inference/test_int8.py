"""int8 engine (OpenVINO + NNCF): parity with float32 on a tiny model, the calibration cache, the
calibration inputs, the precision rules, and the TensorRT backend's refusal without CUDA."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.data.frames import Frame
from semattnet.inference.backends import choose_backend, optimize_for_inference
from semattnet.inference.backends import openvino_int8 as int8_module
from semattnet.inference.backends.calibration import fit_to_size, resolve_calibration
from tests._helpers import random_inputs

SIZE = (64, 96)
needs_int8 = pytest.mark.skipif(
    importlib.util.find_spec("openvino") is None or importlib.util.find_spec("nncf") is None,
    reason="int8 needs openvino and nncf (pip install 'semattnet[openvino]')",
)


@pytest.fixture(scope="module")
def model() -> torch.nn.Module:
    torch.manual_seed(0)
    return semattnet.build_model("semattnet", width=0.125, iterations=2).eval()


@pytest.mark.slow  # ONNX export + OpenVINO conversion + NNCF: about 10 s on 2 idle cores, 25 s loaded
@needs_int8
def test_int8_close_to_float32_and_cached(model: torch.nn.Module, tmp_path: Path, monkeypatch) -> None:
    x = random_inputs(b=1, h=SIZE[0], w=SIZE[1])
    f32 = optimize_for_inference(model, backend="openvino", size=SIZE, cache_dir=tmp_path)(**x).refined_depth
    engine = optimize_for_inference(model, precision="int8", size=SIZE, cache_dir=tmp_path, calibration_frames=2)
    assert (engine.backend, engine.precision) == ("openvino", "int8")  # auto + int8 = openvino
    q = engine(**x).refined_depth
    assert q.shape == f32.shape and torch.isfinite(q).all()
    err = (q - f32).abs()
    assert float(err.mean() / f32.abs().mean()) < 0.05  # loose: 8-bit activations of random weights
    assert 0 < float(err.max())  # really quantised
    assert len(list(tmp_path.glob("engines/*/int8-*/model.xml"))) == 1
    monkeypatch.setattr("nncf.quantize", lambda *a, **k: pytest.fail("quantised again despite the cache"))
    again = optimize_for_inference(
        model, backend="openvino", precision="int8", size=SIZE, cache_dir=tmp_path, calibration_frames=2
    )
    torch.testing.assert_close(again(**x).refined_depth, q)
    other = resolve_calibration(None, SIZE, 3)  # another calibration: another cached IR
    assert other.key != resolve_calibration(None, SIZE, 2).key


def test_int8_is_never_the_default() -> None:
    assert choose_backend("cpu", SIZE) in ("openvino", "torch")
    assert choose_backend("cpu", SIZE, "int8") == "openvino"
    assert choose_backend("cpu", SIZE, "fp16") == "torch"


@pytest.mark.parametrize(
    ("backend", "precision", "size", "words"),
    [
        ("torch", "int8", SIZE, "torch backend runs"),
        ("onnxruntime", "int8", SIZE, "onnxruntime backend runs f32, not"),
        ("openvino", "fp16", SIZE, "openvino backend runs"),
        ("openvino", "int8", None, "size"),
    ],
)
def test_precision_rules(model: torch.nn.Module, backend: str, precision: str, size, words: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=words):
        optimize_for_inference(model, backend=backend, precision=precision, size=size)


def test_tensorrt_refuses_cpu_or_missing_package(model: torch.nn.Module) -> None:
    with pytest.raises((InputError, ImportError)) as info:
        optimize_for_inference(model, backend="tensorrt", size=SIZE, device="cpu")
    assert "\n" not in str(info.value) and ("CUDA" in str(info.value) or "tensorrt" in str(info.value))


def test_fit_to_size_takes_bottom_rows_centred_columns() -> None:
    a = np.arange(4 * 6).reshape(4, 6)
    np.testing.assert_array_equal(fit_to_size(a, (2, 4)), [[13, 14, 15, 16], [19, 20, 21, 22]])
    np.testing.assert_array_equal(fit_to_size(np.ones((1, 2)), (2, 3)), [[0, 0, 0], [1, 1, 0]])


def test_calibration_from_frames_and_folders(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    frames = [
        Frame(f"f{i}", rng.integers(0, 255, (70, 100, 3), dtype=np.uint8), rng.random((70, 100)).astype(np.float32))
        for i in range(3)
    ]
    cal = resolve_calibration(frames, SIZE, count=2)
    feeds = cal.feeds()
    assert len(feeds) == 2 and feeds[0]["rgb"].shape == (1, 3, *SIZE) and feeds[0]["sparse"].shape == (1, 1, *SIZE)
    assert feeds[0]["semantic"].shape == (1, 3, *SIZE)  # the unknown fallback map
    np.testing.assert_array_equal(feeds[1]["sparse"][0, 0], fit_to_size(frames[1].sparse, SIZE))
    assert resolve_calibration(frames[:2], SIZE).key == cal.key  # the same frames: the same cached IR
    assert resolve_calibration(frames[1:], SIZE).key != cal.key
    with pytest.raises(InputError, match="calibration"):
        resolve_calibration(42, SIZE)
    with pytest.raises(InputError, match="not a folder"):
        resolve_calibration(tmp_path / "missing", SIZE)
    with pytest.raises(InputError, match="calibration_frames"):
        resolve_calibration(None, SIZE, 0)


def test_calibration_from_a_folder_of_files(tmp_path: Path) -> None:
    from semattnet.data.io import write_depth, write_image

    for sub in ("rgb", "sparse"):
        (tmp_path / sub).mkdir()
    rgb = np.full((64, 96, 3), 7, np.uint8)
    write_image(tmp_path / "rgb" / "a.png", rgb)
    write_depth(tmp_path / "sparse" / "a.png", np.full((64, 96), 2.0, np.float32))
    feeds = resolve_calibration(tmp_path, SIZE).feeds()
    assert len(feeds) == 1 and float(feeds[0]["rgb"].mean()) == 7.0 and float(feeds[0]["sparse"].max()) == 2.0


def test_quantised_ir_module_keeps_the_stems_and_heads_float() -> None:
    assert any("conv_init" in p for p in int8_module.KEEP_FLOAT)
    assert any("refinement_heads" in p for p in int8_module.KEEP_FLOAT)
    assert any("confidence_fusion" in p for p in int8_module.KEEP_FLOAT)


@needs_int8  # ONNX export + OpenVINO conversion: 11 s on 2 loaded cores (no NNCF)
def test_every_keep_float_pattern_names_layers_of_the_exported_ir(model: torch.nn.Module, tmp_path: Path) -> None:
    """A renamed layer cannot silently leave the float32 set: each pattern matches a node (as NNCF matches)."""
    import openvino as ov

    optimize_for_inference(model, backend="openvino", size=SIZE, cache_dir=tmp_path)
    ir = ov.Core().read_model(str(next(tmp_path.glob("engines/*/model.xml"))))
    int8_module.name_layers(ir)
    names = [op.get_friendly_name() for op in ir.get_ordered_ops()]
    unmatched = [p for p in int8_module.KEEP_FLOAT if not any(re.match(p, n) for n in names)]
    assert not unmatched, f"KEEP_FLOAT patterns that name no layer of the IR: {unmatched}"
    fusion = [n for n in names if n.startswith("confidence_fusion/")]
    assert sorted(fusion) == ["confidence_fusion/depths", "confidence_fusion/sum", "confidence_fusion/weighted"]
    assert not [n for n in names if n.startswith("ConvolutionBackpropData")]  # every transposed conv named
    heads = [op for op in ir.get_ordered_ops() if op.get_friendly_name().startswith("refinement_heads/")]
    assert sorted(op.get_type_name() for op in heads).count("Convolution") == 2  # one per stage, where they begin


def _bench() -> ModuleType:
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_int8_accuracy.py"
    spec = importlib.util.spec_from_file_location("bench_int8_accuracy", path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


def test_int8_benchmark_dry_run(capsys: pytest.CaptureFixture[str]) -> None:
    assert _bench().main(["--dry-run", "--scenes", "2"]) is None
    out = capsys.readouterr().out
    assert "2 scenes at (96, 320)" in out and "semattnet-demo-ref-seed1" in out and "synthetic scenes" in out


@pytest.mark.slow  # two OpenVINO engines and an NNCF quantisation at 96x320: about a minute
@needs_int8
def test_int8_benchmark_on_two_scenes(tmp_path: Path) -> None:
    out = tmp_path / "int8.json"
    found = _bench().main(
        [
            "--weights",
            "semattnet-demo-ref-seed0",
            "--scenes",
            "2",
            "--repeats",
            "1",
            "--calibration-frames",
            "2",
            "--speed-size",
            "64x96",
            "--json",
            str(out),
        ]
    )
    assert found is not None and json.loads(out.read_text()) == found
    r = found["weights"]["semattnet-demo-ref-seed0"]
    assert set(r["change_pct"]) == {"rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"}
    assert 0 < r["max_pixel_change_m"] and r["speedup"] > 0 and found["scenes"] == 2
    assert r["speed_at"]["speedup"] > 0 and found["speed_size"] == [64, 96]
