"""Checkpoint reading: the authors' format, safety against malicious pickles, key reports."""

from __future__ import annotations

import argparse
import os
import sys
import types
from pathlib import Path

import pytest
import torch

import semattnet
from semattnet.weights.checkpoint import (
    CheckpointError,
    StateDictMismatchError,
    UnsafeCheckpointError,
    config_from_state_dict,
    load_checkpoint,
    load_weights,
    save_safetensors,
)
from semattnet.weights.hub import load_model
from tests._helpers import random_inputs


def _authors_checkpoint(path: Path, state_dict: dict) -> Path:
    """Write a checkpoint the way the authors' code did: their own classes pickled inside."""
    metrics = types.ModuleType("metrics")

    class Result:
        def __init__(self) -> None:
            self.rmse, self.mae, self.irmse = 0.7095, 0.2054, 0.0020

    Result.__module__ = "metrics"
    Result.__qualname__ = "Result"
    metrics.Result = Result
    sys.modules["metrics"] = metrics
    try:
        torch.save(
            {
                "epoch": 95,
                "model": state_dict,
                "best_result": Result(),
                "optimizer": {"state": {}, "param_groups": [{"lr": 1e-3}]},
                "args": argparse.Namespace(lr=0.00128, batch_size=8, network_model="e"),
            },
            path,
        )
    finally:
        del sys.modules["metrics"]
    return path


@pytest.fixture(scope="module")
def small() -> torch.nn.Module:
    return semattnet.build_model("semattnet", width=0.125).eval()


def test_reads_authors_format_without_their_code(tmp_path: Path, small) -> None:
    ckpt = load_checkpoint(_authors_checkpoint(tmp_path / "model_best.pth.tar", small.state_dict()))
    assert ckpt.format == "torch" and ckpt.epoch == 95
    assert ckpt.args == {"lr": 0.00128, "batch_size": 8, "network_model": "e"}
    assert ckpt.best_result.rmse == pytest.approx(0.7095)  # an inert record of metrics.Result
    assert ckpt.neutralised == {"metrics.Result"}
    assert "optimizer" in ckpt.extra
    model = semattnet.build_model("semattnet", width=0.125)
    load_weights(model, ckpt)
    for k, v in small.state_dict().items():
        assert torch.equal(model.state_dict()[k], v)


def test_malicious_pickle_is_refused_and_not_run(tmp_path: Path, small) -> None:
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):  # type: ignore[no-untyped-def]
            return (os.system, (f"touch {marker}",))

    path = tmp_path / "evil.pth.tar"
    torch.save({"model": small.state_dict(), "best_result": Evil()}, path)
    with pytest.raises(UnsafeCheckpointError, match=r"evil\.pth\.tar: refusing to load: .*system"):
        load_checkpoint(path)
    assert not marker.exists()


def test_eval_and_import_are_refused(tmp_path: Path) -> None:
    class Sneaky:
        def __reduce__(self):  # type: ignore[no-untyped-def]
            return (eval, ("__import__('os').getcwd()",))

    torch.save({"model": {}, "x": Sneaky()}, tmp_path / "e.pth")
    with pytest.raises(UnsafeCheckpointError, match=r"calls (__builtin__|builtins)\.eval"):
        load_checkpoint(tmp_path / "e.pth")


def test_missing_unexpected_and_shape_mismatch_are_named(small) -> None:
    sd = dict(small.state_dict())
    del sd["att_12.0.weight"]
    sd["extra_head.weight"] = torch.zeros(1)
    sd["mask_layer.0.weight"] = torch.zeros(1, 96, 3, 3)
    model = semattnet.build_model("semattnet", width=0.125)
    with pytest.raises(StateDictMismatchError) as info:
        load_weights(model, sd)
    msg = str(info.value)
    assert "1 missing: att_12.0.weight" in msg
    assert "1 unexpected: extra_head.weight" in msg
    assert "mask_layer.0.weight: checkpoint (1, 96, 3, 3) vs model (1, 12, 3, 3)" in msg
    report = load_weights(model, sd, strict=False)
    assert report["missing"] == ["att_12.0.weight"]


def test_backbone_checkpoint_into_full_model_gets_a_hint() -> None:
    bb = semattnet.build_model("semattnet_backbone", width=0.125)
    with pytest.raises(StateDictMismatchError, match="backbone checkpoint: load it into model.backbone"):
        load_weights(semattnet.build_model("semattnet", width=0.125), bb.state_dict())


def test_ddp_prefix_is_stripped(tmp_path: Path, small) -> None:
    torch.save({f"module.{k}": v for k, v in small.state_dict().items()}, tmp_path / "ddp.pt")
    ckpt = load_checkpoint(tmp_path / "ddp.pt")
    assert ckpt.format == "state_dict" and set(ckpt.state_dict) == set(small.state_dict())


@pytest.mark.parametrize("cut", [0, 100, 5000])
def test_truncated_or_garbage_files_are_refused(tmp_path: Path, small, cut: int) -> None:
    good = tmp_path / "good.pth"
    torch.save(small.state_dict(), good)
    bad = tmp_path / "bad.pth"
    bad.write_bytes(good.read_bytes()[:cut] if cut else b"not a checkpoint at all")
    with pytest.raises(CheckpointError, match="bad.pth"):
        load_checkpoint(bad)
    with pytest.raises(CheckpointError, match="checkpoint file not found"):
        load_checkpoint(tmp_path / "absent.pth")


def test_safetensors_round_trip_and_load_model(tmp_path: Path, small) -> None:
    src = _authors_checkpoint(tmp_path / "a.pth.tar", small.state_dict())
    out = save_safetensors(load_checkpoint(src), tmp_path / "a.safetensors")
    ckpt = load_checkpoint(out)
    assert ckpt.format == "safetensors" and ckpt.epoch == 95 and ckpt.args["batch_size"] == 8
    assert ckpt.config == small.config
    model = load_model(out)
    x = random_inputs(b=1, h=64, w=64)
    with torch.inference_mode():
        assert torch.equal(model(**x).refined_depth, small(**x).refined_depth)


@pytest.mark.parametrize("name", ["semattnet", "semattnet_backbone", "table2_a", "table2_b", "table2_e"])
def test_architecture_is_inferred_from_weights(name: str) -> None:
    model = semattnet.build_model(name, width=0.25)
    assert config_from_state_dict(model.state_dict()) == model.config
