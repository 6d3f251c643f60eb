"""Training: loss goes down, over-fitting, exact resume after SIGKILL, torchrun DDP, stage chaining."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from semattnet.models.layers import set_gradient_checkpointing
from semattnet.models.registry import build_model
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.training.config import TrainConfig
from semattnet.training.trainer import Trainer, train
from semattnet.weights.checkpoint import CheckpointError, load_checkpoint
from semattnet.weights.hub import from_pretrained
from tests._helpers import random_inputs


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("train-data")
    write_synthetic_kitti(out, frames=8, size=(64, 128), seed=0, eval_frames=2, workers=1)
    return out


def tiny(tree: Path, out: Path, **kw) -> TrainConfig:  # type: ignore[no-untyped-def]
    base = {
        "data": str(tree),
        "out": str(out),
        "width": 0.125,
        "crop": (64, 128),
        "batch_size": 2,
        "workers": 0,
        "log_every": 1,
        "epochs": 1000,
        "depth_head_init": (10.0, 15.0),
    }
    return TrainConfig(**(base | kw))


def _losses(run: Path) -> list[float]:
    return [float(r["loss"]) for r in csv.DictReader(open(run / "log.csv")) if r["split"] == "train"]


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "semattnet.cli", *args]


@pytest.mark.parametrize("steps", [60, pytest.param(300, marks=pytest.mark.slow)])
def test_loss_falls(tree: Path, tmp_path: Path, steps: int) -> None:
    train(tiny(tree, tmp_path, max_steps=steps, val_split=""), log=lambda m: None)
    losses = _losses(tmp_path)
    assert len(losses) == steps
    assert np.mean(losses[-15:]) < (0.5 if steps < 100 else 0.25) * np.mean(losses[:15])
    assert (tmp_path / "curves.png").is_file() and (tmp_path / "config.json").is_file()


@pytest.mark.slow  # ~2 min: 100 one-step epochs, each ending in a checkpoint; test_loss_falls[60] runs by default
def test_overfits_one_sample(tmp_path: Path) -> None:
    data = tmp_path / "one"
    write_synthetic_kitti(data, frames=1, size=(64, 128), seed=1, eval_frames=0, workers=1)
    cfg = tiny(
        data,
        tmp_path / "run",
        batch_size=1,
        max_steps=100,
        val_split="",
        flip=False,
        jitter=0.0,
        branch_weights=(0.0,),
        lr=3e-3,
    )
    train(cfg, log=lambda m: None)
    losses = _losses(tmp_path / "run")
    assert np.sqrt(np.mean(losses[-5:])) < 0.25 * np.sqrt(np.mean(losses[:5]))  # RMSE far below its start


def _state(path: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(path).state_dict


@pytest.mark.slow  # ~25 s; tests/reliability/test_training_resume.py covers resume equality by default
def test_exact_resume_after_sigkill(tree: Path, tmp_path: Path) -> None:
    common = [
        "train",
        "--data",
        str(tree),
        "--width",
        "0.125",
        "--crop",
        "64x128",
        "--batch-size",
        "2",
        "--workers",
        "0",
        "--epochs",
        "2",
        "--set",
        "save_every=3",
        "--set",
        "depth_head_init=[10, 15]",
    ]
    whole = tmp_path / "whole"
    subprocess.run(_cli(*common, "--out", str(whole)), check=True, capture_output=True)

    cut = tmp_path / "cut"
    proc = subprocess.Popen(_cli(*common, "--out", str(cut)), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while not (cut / "checkpoints" / "step-00000003.pt").exists():  # mid-epoch 0 (4 batches an epoch)
        assert proc.poll() is None and time.time() < deadline, "training ended before it could be killed"
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    last = load_checkpoint(cut / "checkpoints" / "last.pt")
    assert last.extra["global_step"] < 8, "the run was not interrupted"
    subprocess.run(_cli("train", "--resume", "--out", str(cut)), check=True, capture_output=True)

    a, b = _state(whole / "checkpoints" / "last.pt"), _state(cut / "checkpoints" / "last.pt")
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), f"{k} differs after resume"
    ea, eb = (
        load_checkpoint(whole / "checkpoints" / "last.pt").extra,
        load_checkpoint(cut / "checkpoints" / "last.pt").extra,
    )
    assert ea["global_step"] == eb["global_step"] == 8
    assert ea["optimizer"]["state"][0]["step"] == eb["optimizer"]["state"][0]["step"]
    assert ea["scheduler"] == eb["scheduler"]


@pytest.mark.slow  # ~10 s; tests/inference/test_sharding.py runs torchrun by default
def test_torchrun_two_processes(tree: Path, tmp_path: Path) -> None:
    out = tmp_path / "ddp"
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node",
        "2",
        "-m",
        "semattnet.cli",
        "train",
        "--data",
        str(tree),
        "--out",
        str(out),
        "--width",
        "0.125",
        "--crop",
        "64x128",
        "--batch-size",
        "2",
        "--workers",
        "0",
        "--epochs",
        "1",
        "--set",
        "log_every=1",
    ]
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-4000:]
    assert "2 ranks in sync" in res.stdout
    assert res.stdout.count("done: epoch 1, step 2") == 2  # 8 frames / (2 ranks x batch 2) = 2 steps each
    rows = list(csv.DictReader(open(out / "log.csv")))
    assert [r["step"] for r in rows if r["split"] == "train"] == ["1", "2"]  # one writer, not two
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["best.pt", "last.pt", "step-00000002.pt"]


def test_stage_chaining_and_frozen_backbone(tree: Path, tmp_path: Path) -> None:
    quiet = {"log": lambda m: None}
    train(tiny(tree, tmp_path / "s1", max_steps=2), **quiet)
    s1 = _state(tmp_path / "s1" / "checkpoints" / "last.pt")
    train(
        tiny(tree, tmp_path / "s2", stage="refine-init", init=str(tmp_path / "s1/checkpoints/last.pt"), max_steps=3),
        **quiet,
    )
    s2 = _state(tmp_path / "s2" / "checkpoints" / "last.pt")
    for k, v in s1.items():  # weights and BN statistics of the backbone are untouched
        assert torch.equal(s2["backbone." + k], v), k
    head = [k for k in s2 if k.startswith("iter_guide_layer3.")]
    fresh = build_model("semattnet", width=0.125).state_dict()
    assert any(not torch.equal(s2[k], fresh[k]) for k in head if "num_batches" not in k)
    train(
        tiny(tree, tmp_path / "s3", stage="full", init=str(tmp_path / "s2/checkpoints/last.pt"), max_steps=2), **quiet
    )
    s3 = _state(tmp_path / "s3" / "checkpoints" / "last.pt")
    assert not torch.equal(s3["backbone.rgb_conv_init.0.weight"], s2["backbone.rgb_conv_init.0.weight"])
    assert torch.equal(s3["att_12.0.weight"], s2["att_12.0.weight"])  # dead under the authors' aliasing
    with pytest.raises(ValueError, match="--init"):
        Trainer(tiny(tree, tmp_path / "s4", stage="full"))


def test_weights_only_export_of_a_training_checkpoint(tree: Path, tmp_path: Path) -> None:
    from semattnet.weights.checkpoint import save_safetensors

    train(tiny(tree, tmp_path / "run", max_steps=1, val_split=""), log=lambda m: None)
    ckpt = load_checkpoint(tmp_path / "run" / "checkpoints" / "last.pt")
    assert {"optimizer", "scheduler", "rng", "train_config"} <= set(ckpt.extra)
    out = save_safetensors(ckpt, tmp_path / "release.safetensors")
    model = from_pretrained(out, progress=False)
    assert model.config.width == 0.125 and not model.config.refine
    assert out.stat().st_size < (tmp_path / "run" / "checkpoints" / "last.pt").stat().st_size / 2


def test_corrupt_checkpoint_is_refused_and_previous_kept(tree: Path, tmp_path: Path) -> None:
    train(tiny(tree, tmp_path, max_steps=3, save_every=1, val_split=""), log=lambda m: None)
    last = tmp_path / "checkpoints" / "last.pt"
    last.write_bytes(last.read_bytes()[: len(last.read_bytes()) // 2])
    with pytest.raises(CheckpointError, match="last.pt: not a readable PyTorch checkpoint"):
        Trainer(TrainConfig(out=str(tmp_path)), resume=True)
    kept = sorted(p.name for p in (tmp_path / "checkpoints").glob("step-*.pt"))
    assert kept == ["step-00000001.pt", "step-00000002.pt", "step-00000003.pt"]
    assert load_checkpoint(tmp_path / "checkpoints" / kept[-1]).extra["global_step"] == 3


def test_bf16_autocast_step(tree: Path, tmp_path: Path) -> None:
    result = train(tiny(tree, tmp_path, stage="backbone", amp="bf16", max_steps=2, val_split=""), log=lambda m: None)
    assert result["step"] == 2 and all(np.isfinite(_losses(tmp_path)))


def test_gradient_checkpointing_gives_the_same_gradients() -> None:
    torch.manual_seed(0)
    a = build_model("semattnet", width=0.125).train()
    b = build_model("semattnet", width=0.125).train()
    b.load_state_dict(a.state_dict())
    assert set_gradient_checkpointing(b) == 30
    x = random_inputs(b=2, h=64, w=64)
    for m in (a, b):
        m(**x).refined_depth.square().mean().backward()
    for (n, p), q in zip(a.named_parameters(), b.parameters(), strict=True):
        if p.grad is not None:
            torch.testing.assert_close(p.grad, q.grad, rtol=1e-4, atol=1e-6, msg=n)


def test_config_overrides_and_round_trip(tmp_path: Path) -> None:
    cfg = TrainConfig(stage="full").with_overrides(["epochs=3", "crop=[64, 128]", "amp=bf16"])
    assert cfg.epochs == 3 and cfg.crop == (64, 128) and cfg.batch_size == 16 and cfg.head_lr == 0.025298
    assert cfg.random_crop_height == 320 or cfg.random_crop_height == 64
    cfg.save(tmp_path / "c.json")
    assert TrainConfig.load(tmp_path / "c.json") == cfg
    with pytest.raises(ValueError, match="bad override"):
        cfg.with_overrides(["nope=1"])
    with pytest.raises(ValueError, match="stage"):
        TrainConfig(stage="stage3")
