"""Training semantics: resume equals the uninterrupted run in every saved field; no duplicate log
rows; a run folder is not reused without --resume / --overwrite; sync_bn on CPU is refused."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.training.config import TrainConfig
from semattnet.training.trainer import Trainer, train

STEPS = 6  # 4 batches an epoch: the kill at step 3 is mid-epoch, the end is mid-epoch 1


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("resume-data")
    write_synthetic_kitti(out, frames=8, size=(64, 128), seed=0, eval_frames=2, workers=1)
    return out


def _cfg(tree: Path, out: Path) -> TrainConfig:
    return TrainConfig(
        data=str(tree),
        out=str(out),
        width=0.125,
        crop=(64, 128),
        batch_size=2,
        workers=0,
        log_every=1,
        epochs=5,
        max_steps=STEPS,
        save_every=3,
        val_split="",
        depth_head_init=(10.0, 15.0),
    )


class _Killed(BaseException):
    """Stands for SIGKILL right after the checkpoint of step 3 (nothing after it runs)."""


def _equal(a: Any, b: Any, where: str) -> None:
    if isinstance(a, torch.Tensor):
        assert isinstance(b, torch.Tensor) and torch.equal(a, b), f"{where} differs"
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b), f"{where} differs"
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), f"{where}: keys differ"
        for k in a:
            _equal(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), f"{where}: lengths differ"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _equal(x, y, f"{where}[{i}]")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _raw(path: Path) -> dict[str, Any]:
    return torch.load(path, map_location="cpu", weights_only=False)


def _steps(run: Path) -> list[int]:
    return [int(r["step"]) for r in csv.DictReader(open(run / "log.csv")) if r["split"] == "train"]


def test_resume_equals_the_uninterrupted_run_in_every_saved_field(
    tree: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    train(_cfg(tree, tmp_path / "whole"), log=lambda m: None)
    save = Trainer.save

    def save_then_die(self: Trainer, best: bool = False, periodic: bool = False) -> None:
        save(self, best, periodic)
        if self.pos.step == 3:
            self._write_row({"epoch": 0, "step": 4, "split": "train", "loss": 0.0, "lr": 0.0})  # a row after the save
            raise _Killed

    monkeypatch.setattr(Trainer, "save", save_then_die)
    with pytest.raises(_Killed):
        train(_cfg(tree, tmp_path / "cut"), log=lambda m: None)
    monkeypatch.setattr(Trainer, "save", save)
    assert _raw(tmp_path / "cut" / "checkpoints" / "last.pt")["global_step"] == 3
    train(_cfg(tree, tmp_path / "cut"), resume=True, log=lambda m: None)
    whole, cut = (
        _raw(tmp_path / "whole" / "checkpoints" / "last.pt"),
        _raw(tmp_path / "cut" / "checkpoints" / "last.pt"),
    )
    whole["train_config"].pop("out"), cut["train_config"].pop("out")
    _equal(whole, cut, "last.pt")  # weights, optimiser, scheduler, scaler, RNG states, position, config
    assert _steps(tmp_path / "cut") == _steps(tmp_path / "whole") == list(range(1, STEPS + 1))


@pytest.mark.slow  # ~9 s: trains twice; test_train_overwrite_safety.py tests the refusal by default
def test_a_finished_run_folder_is_not_reused_without_resume_or_overwrite(tree: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    train(_cfg(tree, run), log=lambda m: None)
    (run / "notes.txt").write_text("mine")
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    with pytest.raises(FileExistsError, match="--resume.*--overwrite"):
        train(_cfg(tree, run), log=lambda m: None)
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
    train(_cfg(tree, run), overwrite=True, log=lambda m: None)
    assert (run / "notes.txt").read_text() == "mine"
    assert _steps(run) == list(range(1, STEPS + 1))


def test_sync_bn_on_cpu_is_one_clear_error(tree: Path, tmp_path: Path) -> None:
    cfg = _cfg(tree, tmp_path / "r")
    cfg.sync_bn, cfg.device = True, "cpu"
    with pytest.raises(ValueError, match="sync_bn needs CUDA"):
        train(cfg, log=lambda m: None)


@pytest.mark.parametrize(
    "override",
    [
        "lr=nan",
        "lr=-1",
        "lr=Infinity",
        "epochs=0",
        "batch_size=-2",
        "workers=-1",
        "width=0",
        "betas=[1.5, 0.9]",
        "crop=[0, 10]",
        "log_every=0",
        "max_steps=-5",
        'sync_bn="yes"',
        "jitter=NaN",
    ],
)
def test_config_refuses_nonsense(override: str) -> None:
    with pytest.raises(ValueError, match=override.split("=")[0]):
        TrainConfig().with_overrides([override])
