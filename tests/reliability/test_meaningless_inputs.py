"""Inputs that mean nothing are refused, the same way by the classical completer, the model and the CLI:
no valid point, no point inside the image, bad intrinsics, NaN / inf / negative / huge depth, ignored
options, a zero std, invalid devices."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from semattnet._errors import InputError
from semattnet._utils.bounds import check_pinhole
from semattnet._utils.device import resolve_device
from semattnet.baselines.classical import ClassicalCompleter, complete_classical
from semattnet.cli import main
from semattnet.data.io import write_depth, write_image
from semattnet.models.checks import MAX_INPUT_DEPTH_M, check_inputs

BAD_DEPTH = {
    "nan": float("nan"),
    "inf": float("inf"),
    "-inf": -float("inf"),
    "negative": -1.0,
    "huge": MAX_INPUT_DEPTH_M * 1.5,
}


@pytest.fixture(scope="module")
def model_completer():  # type: ignore[no-untyped-def]
    import semattnet
    from semattnet.inference import DepthCompleter
    from semattnet.inference.backends import EngineSpec

    torch.manual_seed(0)
    return DepthCompleter(semattnet.build_model("semattnet", width=0.125).eval(), EngineSpec(device="cpu"))


def _frame(value: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sparse = np.zeros((32, 32), np.float32)
    sparse[10, 10] = 5.0
    if value is not None:
        sparse[3, 4] = value
    return np.zeros((32, 32, 3), np.float32), sparse, np.zeros((32, 32, 3), np.float32)


def _message(fn) -> str:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError) as err:
        fn()
    assert "\n" not in str(err.value)
    return str(err.value)


@pytest.mark.parametrize("kind", sorted(BAD_DEPTH))
def test_classical_and_model_refuse_bad_depth_with_one_message(kind: str, model_completer) -> None:  # type: ignore[no-untyped-def]
    rgb, sparse, sem = _frame(BAD_DEPTH[kind])
    classical = _message(lambda: ClassicalCompleter()(rgb, sparse))
    model = _message(lambda: model_completer(rgb, sparse, sem))
    tensor = _message(lambda: complete_classical(torch.from_numpy(sparse)[None, None]))
    forward = _message(
        lambda: check_inputs(
            torch.zeros(1, 3, 32, 32),
            torch.zeros(1, 3, 32, 32),
            torch.from_numpy(sparse)[None, None],
            need_semantic=True,
        )
    )
    assert classical == model == tensor == forward


def test_a_map_without_valid_points_is_refused_by_both(model_completer) -> None:  # type: ignore[no-untyped-def]
    rgb, sparse, sem = _frame(None)
    sparse[:] = 0
    assert _message(lambda: ClassicalCompleter()(rgb, sparse)) == _message(lambda: model_completer(rgb, sparse, sem))
    assert "no valid depth point" in _message(lambda: ClassicalCompleter()(rgb, sparse))


def test_valid_depths_up_to_the_bound_still_complete() -> None:
    rgb, sparse, _ = _frame(MAX_INPUT_DEPTH_M)
    assert ClassicalCompleter()(rgb, sparse).depth.shape == (32, 32)


def test_predict_cli_refuses_a_map_without_points(tmp_path: Path) -> None:
    write_image(tmp_path / "rgb" / "a.png", np.zeros((8, 12, 3), np.uint8))
    write_depth(tmp_path / "sparse" / "a.png", np.zeros((8, 12)))
    res = CliRunner().invoke(
        main,
        [
            "predict",
            "--method",
            "classical",
            "--rgb",
            str(tmp_path / "rgb"),
            "--sparse",
            str(tmp_path / "sparse"),
            "--out",
            str(tmp_path / "out"),
        ],
    )
    assert res.exit_code == 1 and "no valid depth point" in res.output, res.output
    assert not list((tmp_path / "out").glob("*.png")) if (tmp_path / "out").exists() else True


@pytest.mark.parametrize(
    "K",
    [
        (float("nan"), 1, 1, 1),
        (1, float("inf"), 1, 1),
        (0, 1, 1, 1),
        (-5, 1, 1, 1),
        (1, 1, float("nan"), 1),
        (1, 1, 1, -float("inf")),
    ],
)
def test_bad_intrinsics(K: tuple[float, ...]) -> None:
    assert "fx, fy" in _message(lambda: check_pinhole(*K))


@pytest.mark.parametrize("K", ["nan,50,16,12", "50,inf,16,12", "0,50,16,12", "50,50,nan,12"])
def test_project_and_predict_refuse_bad_K(tmp_path: Path, K: str) -> None:
    np.save(tmp_path / "s.npy", np.array([[5.0, 0, 0]], np.float32))
    res = CliRunner().invoke(
        main,
        [
            "project",
            "--points",
            str(tmp_path / "s.npy"),
            "--K",
            K,
            "--T",
            "0,-1,0,0,0,0,-1,0,1,0,0,0,0,0,0,1",
            "--size",
            "32x24",
            "--out",
            str(tmp_path / "o.png"),
        ],
    )
    assert res.exit_code == 1 and "--K" in res.output and not (tmp_path / "o.png").exists(), res.output
    res = CliRunner().invoke(
        main,
        [
            "predict",
            "--method",
            "classical",
            "--rgb",
            str(tmp_path),
            "--sparse",
            str(tmp_path),
            "--K",
            K,
            "--out",
            str(tmp_path / "p"),
        ],
    )
    assert res.exit_code == 2 and "--K" in res.output and "Traceback" not in res.output, res.output


def test_a_scan_with_no_point_in_the_image_is_refused(tmp_path: Path) -> None:
    T = [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]]
    rig = {"K": [[50, 0, 16], [0, 50, 12], [0, 0, 1]], "T_cam_lidar": T, "image_size": [32, 24]}
    (tmp_path / "rig.json").write_text(json.dumps(rig))
    for name, pts in (("behind", [[-5.0, 0, 0]]), ("aside", [[1.0, 50.0, 0]]), ("above", [[1.0, 0, 40.0]])):
        np.save(tmp_path / f"{name}.npy", np.array(pts, np.float32))
        args = ["project", "--points", tmp_path / f"{name}.npy", "--rig", tmp_path / "rig.json"]
        res = CliRunner().invoke(main, [str(a) for a in [*args, "--out", tmp_path / f"{name}.png"]])
        said = "none of its 1 points" in res.output or "no point in front" in res.output
        assert res.exit_code == 1 and said and f"{name}.npy" in res.output, res.output
        assert not (tmp_path / f"{name}.png").exists()


def test_classical_with_weights_is_refused(tmp_path: Path) -> None:
    weights = tmp_path / "w.safetensors"
    weights.write_bytes(b"x")
    args = ["predict", "--method", "classical", "--weights", weights, "--rgb", tmp_path, "--sparse", tmp_path]
    res = CliRunner().invoke(main, [str(a) for a in [*args, "--out", tmp_path / "o"]])
    assert res.exit_code == 2 and "--method classical uses no model" in res.output, res.output


@pytest.mark.parametrize("std", ["0,0,0", "1,0,1", "-1,1,1", "nan,1,1", "inf,1,1"])
def test_segment_refuses_a_std_that_is_not_positive(tmp_path: Path, std: str) -> None:
    write_image(tmp_path / "im" / "a.png", np.zeros((4, 4, 3), np.uint8))
    res = CliRunner().invoke(
        main,
        ["segment", "--model", "unknown", "--images", str(tmp_path / "im"), "--out", str(tmp_path / "o"), "--std", std],
    )
    assert res.exit_code == 1 and "--std" in res.output and not (tmp_path / "o").exists(), res.output


@pytest.mark.parametrize("name", ["meta", "foo", "cuda:abc", "cuda:-1", "", "cpu:0:1", "xla"])
def test_invalid_devices_are_one_line(name: str) -> None:
    assert "device" in _message(lambda: resolve_device(name))


def test_valid_devices() -> None:
    assert resolve_device("cpu").type == "cpu" and resolve_device(torch.device("cpu")).type == "cpu"
    assert resolve_device("auto").type in ("cpu", "cuda")


@pytest.mark.parametrize("name", ["meta", "foo", "cuda:abc"])
def test_predict_device_option(tmp_path: Path, name: str) -> None:
    weights = tmp_path / "w.safetensors"
    weights.write_bytes(b"x")
    res = CliRunner().invoke(
        main,
        [
            "predict",
            "--weights",
            str(weights),
            "--device",
            name,
            "--rgb",
            str(tmp_path),
            "--sparse",
            str(tmp_path),
            "--out",
            str(tmp_path / "o"),
        ],
    )
    assert res.exit_code == 1 and "device" in res.output and len(res.output.strip().splitlines()) == 1, res.output
    assert isinstance(res.exception, SystemExit)
