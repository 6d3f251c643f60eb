"""``train --overwrite`` destroys nothing before the replacement is ready: the new run is built (data, model,
optimiser) and trains with the earlier run's files left whole; they are replaced only once the new run has its
first checkpoint, through a stage folder that a failed or killed run leaves for the next run to clear."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

from semattnet._utils.run_folder import REPLACE_PREFIX
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.training.config import TrainConfig
from semattnet.training.trainer import Trainer, run_files, train


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("overwrite-data")
    write_synthetic_kitti(out, frames=8, size=(64, 128), seed=0, eval_frames=2, workers=1)
    return out


def _cfg(tree: Path, out: Path, **kw: object) -> TrainConfig:
    fields = {
        "data": str(tree),
        "out": str(out),
        "width": 0.125,
        "crop": (64, 128),
        "batch_size": 2,
        "workers": 0,
        "log_every": 1,
        "epochs": 5,
        "max_steps": 2,
        "save_every": 1,
        "keep_last": 2,
        "val_split": "",
        "depth_head_init": (10.0, 15.0),
    }
    return TrainConfig(**(fields | kw))  # type: ignore[arg-type]


def _quiet(line: str) -> None:
    pass


def _digests(out: Path) -> dict[str, str]:
    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(out.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def finished(tree: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished run of 2 steps, a checkpoint each (not to be changed: see :func:`earlier`)."""
    out = tmp_path_factory.mktemp("finished") / "run"
    train(_cfg(tree, out), log=_quiet)
    assert {"checkpoints/last.pt", "checkpoints/step-00000001.pt", "log.csv"} <= set(run_files(out))
    return out


@pytest.fixture
def earlier(finished: Path, tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A copy of :func:`finished` in ``tmp_path/run`` with a user's file beside it, and the digests of every file."""
    out = tmp_path / "run"
    shutil.copytree(finished, out)
    (out / "notes.txt").write_text("mine")
    return out, _digests(out)


def test_an_overwrite_from_data_that_cannot_be_read_keeps_the_earlier_run(
    earlier: tuple[Path, dict[str, str]], tmp_path: Path
) -> None:
    out, before = earlier
    with pytest.raises((OSError, ValueError)):
        train(_cfg(tmp_path / "no-such-data", out), overwrite=True, log=_quiet)
    assert _digests(out) == before


def test_an_overwrite_that_fails_before_its_first_checkpoint_keeps_the_earlier_run_and_leaves_no_stage(
    earlier: tuple[Path, dict[str, str]], tree: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out, before = earlier
    step = Trainer._step

    def second_step_fails(self: Trainer, *args: object) -> float:
        if self.pos.step == 1:
            raise RuntimeError("out of memory at step 2")
        return step(self, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(Trainer, "_step", second_step_fails)
    with pytest.raises(RuntimeError, match="step 2"):
        train(_cfg(tree, out, seed=1, save_every=0), overwrite=True, log=_quiet)
    assert _digests(out) == before  # the stage of the failed run is gone too


def test_a_finished_overwrite_replaces_the_earlier_runs_files_and_nothing_else(
    earlier: tuple[Path, dict[str, str]], tree: Path
) -> None:
    out, before = earlier
    train(_cfg(tree, out, seed=1, save_every=0), overwrite=True, log=_quiet)
    after = _digests(out)
    assert after["notes.txt"] == before["notes.txt"]
    assert not any(f.startswith("checkpoints/step-") for f in after)  # the earlier run's numbered checkpoints
    assert after["checkpoints/last.pt"] != before["checkpoints/last.pt"] and after["log.csv"] != before["log.csv"]
    assert not list(out.glob(f"{REPLACE_PREFIX}*"))
