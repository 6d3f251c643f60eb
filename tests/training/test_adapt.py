"""``semattnet.training.adapt``: a normal checkpoint out, bad frames skipped and counted, exact resume, the held-out
metric, the run folder's rules, the configuration's checks, DDP under torchrun."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.distributed as dist

from semattnet._errors import DataError, InputError
from semattnet._utils import distributed as dist_utils
from semattnet.data.frames import Frame, IndexedSource
from semattnet.training.adapt import FINAL, LOG, STATE, AdaptConfig, Adapter, adapt
from semattnet.weights.checkpoint import load_checkpoint
from semattnet.weights.hub import from_pretrained

SIZE = (32, 64)


class _Frames(IndexedSource):
    """Random frames in memory, with ground truth; the ``bad`` ones fail to read as a corrupt file does."""

    def __init__(self, n: int = 3, bad: tuple[str, ...] = ()) -> None:
        self.names = [f"f{i}" for i in range(n)]
        self.bad = bad

    def load(self, name: str) -> Frame:
        if name in self.bad:
            raise DataError(f"{name}.png: not a PNG file")
        rng = np.random.default_rng(int(name[1:]))
        gt = rng.uniform(5, 40, SIZE).astype(np.float32)
        sparse = np.where(rng.random(SIZE) < 0.3, gt, 0).astype(np.float32)
        rgb = rng.integers(0, 256, (*SIZE, 3), dtype=np.uint8)
        return Frame(name, rgb, sparse, gt=gt)

    def inputs(self) -> list[Path]:
        return []


def _cfg(weights: Path, out: Path, **kw: object) -> AdaptConfig:
    return AdaptConfig(
        **({"weights": str(weights), "out": str(out), "steps": 2, "batch_size": 1, "crop": SIZE, "device": "cpu"} | kw)
    )  # type: ignore[arg-type]


def _quiet(msg: str) -> None:
    pass


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_adapt_writes_a_normal_checkpoint_and_skips_bad_frames(tiny_weights: Path, tmp_path: Path) -> None:
    lines: list[str] = []
    result = adapt(_cfg(tiny_weights, tmp_path / "run"), _Frames(3, bad=("f1",)), log=lines.append)
    assert result.step == 2 and result.frames == 2
    assert [(f.name, f.status) for f in result.skipped] == [("f1", "skipped")] and "f1.png" in result.skipped[0].reason
    assert "f1: skipped: f1.png: not a PNG file" in lines
    assert any("no other view" in line for line in lines)  # the photometric loss asked for, and left out
    adapted = from_pretrained(tmp_path / "run" / FINAL)  # what predict --weights reads; so is the state
    state = from_pretrained(tmp_path / "run" / STATE)
    before = load_checkpoint(tiny_weights).state_dict
    after = adapted.state_dict()
    assert any(not torch.equal(before[k], after[k]) for k in before)
    assert all(torch.equal(after[k], v) for k, v in state.state_dict().items())
    log = json.loads((tmp_path / "run" / LOG).read_text())
    assert [r["step"] for r in log["steps"]] == [1, 2] and {"sparse", "smoothness"} <= set(log["steps"][0])
    assert log["skipped"][0]["name"] == "f1" and log["frames"] == 2


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_a_bad_frame_stops_the_run_with_on_error_stop_and_no_usable_frame_is_one_line(
    tiny_weights: Path, tmp_path: Path
) -> None:
    with pytest.raises(DataError, match=r"f0\.png: not a PNG"):
        adapt(_cfg(tiny_weights, tmp_path / "a", on_error="stop"), _Frames(2, bad=("f0",)), log=_quiet)
    with pytest.raises(DataError, match="none of its 2 frame"):
        adapt(_cfg(tiny_weights, tmp_path / "b"), _Frames(2, bad=("f0", "f1")), log=_quiet)


class _Killed(BaseException):
    """Stands for SIGKILL right after the state of step 1 is written."""


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_resume_equals_the_uninterrupted_run(
    tiny_weights: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cfg = {"steps": 3, "save_every": 1}
    adapt(_cfg(tiny_weights, tmp_path / "whole", **cfg), _Frames(), log=_quiet)
    save = Adapter.save

    def save_then_die(self: Adapter) -> None:
        save(self)
        if self.step == 1:
            raise _Killed

    monkeypatch.setattr(Adapter, "save", save_then_die)
    with pytest.raises(_Killed):
        adapt(_cfg(tiny_weights, tmp_path / "cut", **cfg), _Frames(), log=_quiet)
    monkeypatch.setattr(Adapter, "save", save)
    with pytest.raises(FileExistsError, match="--resume"):
        adapt(_cfg(tiny_weights, tmp_path / "cut", **cfg), _Frames(), log=_quiet)
    adapt(_cfg(tiny_weights, tmp_path / "cut", **cfg), _Frames(), resume=True, log=_quiet)
    a, b = (load_checkpoint(tmp_path / run / FINAL).state_dict for run in ("whole", "cut"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    logs = [json.loads((tmp_path / run / LOG).read_text())["steps"] for run in ("whole", "cut")]
    assert [r["loss"] for r in logs[0]] == [r["loss"] for r in logs[1]]


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_a_run_killed_between_the_log_and_the_state_resumes_with_the_log_of_every_step(
    tiny_weights: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from semattnet.training.adapt import run

    writes, atomic_path = [], run.atomic_path

    def die_at_the_fourth_write(path: Path, **kw: object):  # type: ignore[no-untyped-def]
        writes.append(path)
        if len(writes) == 4:  # step 2: its first file is written, the second never is
            raise _Killed
        return atomic_path(path, **kw)

    monkeypatch.setattr(run, "atomic_path", die_at_the_fourth_write)
    with pytest.raises(_Killed):
        adapt(_cfg(tiny_weights, tmp_path, steps=2, save_every=1), _Frames(), log=_quiet)
    monkeypatch.setattr(run, "atomic_path", atomic_path)
    adapt(_cfg(tiny_weights, tmp_path), _Frames(), resume=True, log=_quiet)
    assert [r["step"] for r in json.loads((tmp_path / LOG).read_text())["steps"]] == [1, 2]


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_the_held_out_metric_uses_frames_kept_out_of_training(tiny_weights: Path, tmp_path: Path) -> None:
    adapter = Adapter(_cfg(tiny_weights, tmp_path, steps=1, gt_every=1, gt_frames=1), _Frames(3), log=_quiet)
    assert adapter.pool.held_out == ["f2"] and adapter.pool.names == ["f0", "f1"]
    result = adapter.run()
    assert result.metrics is not None and result.metrics["rmse_mm"] > 0
    assert [m["step"] for m in json.loads((tmp_path / LOG).read_text())["metrics"]] == [1]


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("crop", (30, 64), "multiples of 32"),
        ("hide", (0.3, 0.2), "hide"),
        ("losses", ("sparse", "depth"), "losses"),
        ("steps", 0, "steps"),
        ("amp", "fp8", "amp"),
        ("lr", float("nan"), "lr"),
    ],
)
def test_the_config_refuses_what_cannot_run(field: str, value: object, match: str) -> None:
    with pytest.raises(InputError, match=match):
        AdaptConfig(**{"weights": "w", "out": "o", field: value})  # type: ignore[arg-type]


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "semattnet.cli", "adapt", *args]


@pytest.mark.slow  # ~20 s: three processes on the real frame
def test_a_run_killed_with_sigkill_and_resumed_ends_with_the_uninterrupted_weights(
    tiny_weights: Path, tmp_path: Path
) -> None:
    drive = Path(__file__).resolve().parents[1] / "data/kitti_sample/kitti_raw/2011_09_26/2011_09_26_drive_0035_sync"
    common = [
        "--kitti-raw",
        str(drive),
        "--weights",
        str(tiny_weights),
        "--crop",
        "32x64",
        "--batch-size",
        "1",
        "--steps",
        "6",
        "--save-every",
        "2",
        "--device",
        "cpu",
    ]
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    subprocess.run(_cli(*common, "--out", str(tmp_path / "whole")), check=True, capture_output=True, env=env)
    cut = tmp_path / "cut"
    proc = subprocess.Popen(
        _cli(*common, "--out", str(cut)), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
    )
    deadline = time.time() + 300
    while not (cut / STATE).exists():
        assert proc.poll() is None and time.time() < deadline, "the run ended before it could be killed"
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert load_checkpoint(cut / STATE).extra["step"] < 6, "the run was not interrupted"
    subprocess.run(
        _cli("--kitti-raw", str(drive), "--out", str(cut), "--resume"), check=True, capture_output=True, env=env
    )
    a, b = (load_checkpoint(tmp_path / run / FINAL).state_dict for run in ("whole", "cut"))
    assert all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.filterwarnings("ignore:no semantic maps given")
def test_a_process_group_of_one_runs_the_ddp_path_and_resume_needs_as_many_processes(
    tiny_weights: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    lines: list[str] = []
    dist.init_process_group("gloo", store=dist.HashStore(), rank=0, world_size=1)
    try:
        adapt(_cfg(tiny_weights, tmp_path, steps=1), _Frames(), log=lines.append)
    finally:
        if dist.is_initialized():
            dist.destroy_process_group()
    assert any(line.startswith("1 ranks in sync (parameter checksum") for line in lines)
    rng = load_checkpoint(tmp_path / STATE).extra["rng"]
    assert isinstance(rng, list) and len(rng) == 1  # each rank's generator
    monkeypatch.setattr(dist_utils, "world_size", lambda: 2)
    with pytest.raises(InputError, match=r"ran as 1 process\(es\), this is 2; .*--nproc_per_node 1"):
        Adapter(_cfg(tiny_weights, tmp_path), _Frames(), resume=True, log=_quiet)
    with pytest.raises(InputError, match="--train-bn with several processes needs CUDA"):
        Adapter(_cfg(tiny_weights, tmp_path / "bn", freeze_bn=False), _Frames(), log=_quiet)


def _torchrun(*args: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node",
        "2",
        "-m",
        "semattnet.cli",
        "adapt",
        *args,
    ]


def _kill_workers_after_the_first_state(proc: subprocess.Popen[bytes], out: Path) -> None:
    """SIGKILL torchrun's worker processes (a crash of every rank) once ``out`` holds a state, then the launcher."""
    deadline = time.time() + 300
    while not (out / STATE).exists():
        assert proc.poll() is None and time.time() < deadline, "the run ended before it could be killed"
        time.sleep(0.02)
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
    for pid in children:
        os.kill(int(pid), signal.SIGKILL)
    proc.kill()
    proc.wait()


@pytest.mark.slow  # ~40 s: three torchrun launches of two processes
def test_torchrun_two_processes_and_a_killed_run_resumed_under_torchrun(tiny_weights: Path, tmp_path: Path) -> None:
    drive = Path(__file__).resolve().parents[1] / "data/kitti_sample/kitti_raw/2011_09_26/2011_09_26_drive_0035_sync"
    common = [
        "--kitti-raw",
        str(drive),
        "--weights",
        str(tiny_weights),
        "--crop",
        "32x64",
        "--batch-size",
        "1",
        "--steps",
        "6",
        "--save-every",
        "2",
        "--device",
        "cpu",
    ]
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    res = subprocess.run(_torchrun(*common, "--out", str(whole)), capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-4000:]
    assert res.stdout.count("2 ranks in sync") == 1 and res.stdout.count("done: step 6") == 1  # rank 0 alone
    assert [r["step"] for r in json.loads((whole / LOG).read_text())["steps"]] == [1, 2, 3, 4, 5, 6]
    rng = load_checkpoint(whole / STATE).extra["rng"]
    draws = [torch.rand(8, generator=torch.Generator().set_state(state)) for state in rng]
    assert len(draws) == 2 and not torch.equal(*draws)  # each rank draws its own crops and points
    proc = subprocess.Popen(
        _torchrun(*common, "--out", str(cut)), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
    )
    _kill_workers_after_the_first_state(proc, cut)
    assert load_checkpoint(cut / STATE).extra["step"] < 6, "the run was not interrupted"
    res = subprocess.run(
        _torchrun("--kitti-raw", str(drive), "--out", str(cut), "--resume"),
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-4000:]
    a, b = (load_checkpoint(run / FINAL).state_dict for run in (whole, cut))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    logs = [json.loads((run / LOG).read_text())["steps"] for run in (whole, cut)]
    assert logs[0] == logs[1]
