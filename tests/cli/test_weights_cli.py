"""``semattnet weights list/fetch`` and ``--weights`` on info, convert, bench and ``train --init-weights``."""

from __future__ import annotations

import functools
import threading
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import click
import pytest
import torch
from click.testing import CliRunner
from safetensors.torch import save_file

import semattnet
from semattnet.cli import main
from semattnet.weights import pretrained, sha256_file
from semattnet.weights.pretrained import PretrainedWeights
from tests._helpers import online_cache

NAME = "tiny-test"
CONFIG = {"width": 0.125, "iterations": 2}


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture(scope="module")
def weights_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Safetensors weights of the smallest full model."""
    torch.manual_seed(0)
    model = semattnet.build_model("semattnet", **CONFIG)
    path = tmp_path_factory.mktemp("w") / "tiny.safetensors"
    save_file({k: v.contiguous() for k, v in model.state_dict().items()}, str(path))
    return path


@pytest.fixture
def served(weights_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """``weights_file`` on an HTTP server on 127.0.0.1, registered as NAME; an empty cache."""
    online_cache(monkeypatch, tmp_path / "cache")
    handler = functools.partial(_Quiet, directory=str(weights_file.parent))
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{httpd.server_address[1]}/{weights_file.name}"
    record = PretrainedWeights(
        name=NAME,
        arch="semattnet",
        urls=(url,),
        file_name="tiny.safetensors",
        format="safetensors",
        license="test only: not for release",
        config=CONFIG,
        num_params=5_700_000,
        paper_metrics={"synthetic/val": {"rmse_mm": 1234.5}},
    )
    pretrained.register_weights(record)
    try:
        yield url
    finally:
        pretrained.WEIGHTS.remove(NAME)
        httpd.shutdown()
        httpd.server_close()


def run(*args: str) -> str:
    res = CliRunner().invoke(main, list(args))
    assert res.exit_code == 0, res.output
    return res.output


def test_list_shows_the_registry() -> None:
    out = run("weights", "list")
    header = out.splitlines()[0].split()
    assert header[:6] == ["name", "arch", "params", "trained", "on", "file"]
    row = next(line for line in out.splitlines() if line.startswith("semattnet-kitti"))
    assert "unknown (pinned on first download)" in row and "709.41 mm" in row and "361.0 M" in row
    assert "KITTI depth completion" in row
    for seed in (0, 1):  # the trained weights shipped inside the package, with what they were trained on
        row = next(line for line in out.splitlines() if line.startswith(f"semattnet-demo-ref-seed{seed} "))
        assert "synthetic street scenes (demo)" in row and "5.7 M" in row and "synthetic/own-val" in row


def test_fetch_prints_path_and_sha_then_list_shows_the_pin(served: str, weights_file: Path, tmp_path: Path) -> None:
    out = run("weights", "fetch", NAME, "--no-progress")
    sha = sha256_file(weights_file)
    path = Path(out.split("path:", 1)[1].split()[0])
    assert path.is_file() and path.is_relative_to(tmp_path / "cache") and f"sha256: {sha}" in out
    row = next(line for line in run("weights", "list").splitlines() if line.startswith(NAME))
    assert f"{sha} (pinned)" in row and "1234.5 mm" in row and "test only" in row


def test_fetch_unknown_name_is_one_line_error() -> None:
    res = CliRunner().invoke(main, ["weights", "fetch", "no-such-weights"])
    assert res.exit_code == 2 and "semattnet-kitti" in res.output


def test_info_and_convert_take_weights(served: str, tmp_path: Path) -> None:
    assert '"width": 0.125' in run("info", "--weights", NAME)
    assert '"width": 0.125' in run("info", "--weights", served)  # a URL
    dst = tmp_path / "out.safetensors"
    run("convert", "--weights", NAME, str(dst))
    assert dst.is_file()
    bad = CliRunner().invoke(main, ["info"])
    assert bad.exit_code == 2 and "--weights" in bad.output
    both = CliRunner().invoke(main, ["convert", str(dst), str(tmp_path / "x"), "--weights", NAME])
    assert both.exit_code == 2


def test_bench_takes_weights(served: str) -> None:
    out = run("bench", "--weights", NAME, "--parts", "full", "--size", "32x64", "--repeats", "1", "--device", "cpu")
    assert "full" in out


def test_train_init_weights_resolves_to_a_cached_file(
    served: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import semattnet.training.trainer as trainer

    seen = {}

    def fake_train(cfg, resume=False, log=print, **kw):
        seen["init"] = cfg.init
        return {"epoch": 0, "step": 0, "best_rmse_mm": 0.0}

    monkeypatch.setattr(trainer, "train", fake_train)
    run("train", "--stage", "full", "--data", str(tmp_path), "--out", str(tmp_path / "run"), "--init-weights", NAME)
    assert Path(seen["init"]).is_file() and Path(seen["init"]).is_relative_to(tmp_path / "cache")
    local = tmp_path / "x.pth"
    local.write_bytes(b"")
    both = CliRunner().invoke(main, ["train", "--init", str(local), "--init-weights", NAME])
    assert both.exit_code == 2 and "not both" in both.output and "--init-weights is an alias of --init" in both.output
    missing = CliRunner().invoke(main, ["train", "--init", str(tmp_path / "missing.pth")])
    assert missing.exit_code == 2 and "missing.pth" in missing.output


def _commands(group: click.Group, prefix: str = "") -> dict[str, click.Command]:
    out: dict[str, click.Command] = {}
    for name, cmd in group.commands.items():
        out[prefix + name] = cmd
        if isinstance(cmd, click.Group):
            out.update(_commands(cmd, f"{prefix}{name} "))
    return out


def test_weights_and_checkpoint_are_one_option_on_every_loading_command() -> None:
    loading = {}
    for name, cmd in _commands(main).items():
        flagged = [p for p in cmd.params if {"--weights", "--checkpoint"} & set(p.opts)]
        if flagged:
            (param,) = flagged  # one option, never two
            loading[name] = param
    assert {"predict", "evaluate", "submit", "bench", "info", "convert"} <= set(loading)
    for name, param in loading.items():
        assert param.name == "weights" and param.opts == ["--weights", "--checkpoint"], name
        assert "--checkpoint is an alias" in (param.help or ""), name


def test_checkpoint_spelling_gives_the_same_and_twice_is_refused(served: str, tmp_path: Path) -> None:
    first = run("info", "--weights", NAME)  # downloads (and announces the pin), then the cache answers
    assert run("info", "--checkpoint", NAME) == run("info", "--weights", NAME) and first.startswith("file:")
    both = CliRunner().invoke(main, ["info", "--checkpoint", NAME, "--weights", NAME])
    assert both.exit_code == 2 and "exactly one of --checkpoint or --weights, not both" in both.output
    missing = CliRunner().invoke(main, ["bench", "--checkpoint", str(tmp_path / "none.pt")])
    assert missing.exit_code == 2 and "none.pt" in missing.output and "'--weights' / '--checkpoint'" in missing.output


def test_predict_with_a_shipped_name_end_to_end(tmp_path: Path) -> None:
    """``predict --weights semattnet-demo-ref-seed0``: the registry name, resolved once, completes a frame."""
    import numpy as np

    from semattnet.data.io import read_depth, write_depth, write_image

    rng = np.random.default_rng(0)
    write_image(tmp_path / "rgb" / "f.png", rng.integers(0, 256, (32, 64, 3), dtype=np.uint8))
    write_image(tmp_path / "semantic" / "f.png", np.full((32, 64, 3), (128, 64, 128), np.uint8))
    sparse = np.where(rng.random((32, 64)) < 0.1, rng.uniform(1, 50, (32, 64)), 0).astype(np.float32)
    write_depth(tmp_path / "sparse" / "f.png", sparse)
    out = tmp_path / "out"
    run(
        "predict",
        "--weights",
        "semattnet-demo-ref-seed0",
        "--rgb",
        str(tmp_path / "rgb"),
        "--sparse",
        str(tmp_path / "sparse"),
        "--semantic",
        str(tmp_path / "semantic"),
        "--out",
        str(out),
    )
    depth = read_depth(out / "f.png")
    assert depth.shape == (32, 64) and np.isfinite(depth).all() and (depth > 0).mean() > 0.9


def test_info_reads_names_and_folders_with_their_config(tmp_path: Path) -> None:
    shown = run("info", "semattnet-demo-ref-seed1")
    assert "(packed)" in shown and '"width": 0.125' in shown
    folder = semattnet.weights.save_pretrained(
        semattnet.build_model("semattnet", **CONFIG, refinement_mode="clean"), tmp_path / "folder"
    )
    shown = run("info", str(folder))
    assert "model.safetensors" in shown and '"refinement_mode": "clean"' in shown  # config.json, not dropped
    bad = CliRunner().invoke(main, ["info", str(tmp_path / "nothing-here")])
    assert bad.exit_code == 2 and "known: semattnet-kitti" in bad.output


def test_bench_takes_precision_and_outputs_through_the_shared_options(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--precision f32`` keeps the float32 rows; ``--outputs refined_depth`` builds engines that return what a
    robot reads (an OpenVINO graph cut to it)."""
    from semattnet.apps import benchmark

    asked: list[object] = []
    real = benchmark.optimize_for_inference
    monkeypatch.setattr(
        benchmark, "optimize_for_inference", lambda *a, **k: asked.append(k["outputs"]) or real(*a, **k)
    )
    out = run(
        "bench",
        "--parts",
        "backends",
        "--precision",
        "f32",
        "--size",
        "32x64",
        "--repeats",
        "1",
        "--device",
        "cpu",
        "--width",
        "0.125",
        "--outputs",
        "refined_depth",
    )
    rows = [line for line in out.splitlines() if "backend " in line]
    assert rows and all("(f32)" in line for line in rows), out
    assert asked and set(asked) == {("refined_depth",)}
    refused = (
        (["--calibration", "."], "--calibration only mean(s) something with --precision int8"),
        (["--precision", "f32", "--parts", "full"], "backends is not in --parts"),
        (["--outputs", "refined_depth,depth_map"], "--outputs: unknown output(s) ['depth_map']"),
    )
    for args, message in refused:
        res = CliRunner().invoke(main, ["bench", *args])
        assert res.exit_code != 0 and message in res.output, res.output
