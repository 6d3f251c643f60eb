"""The frame loop's write stage (:mod:`semattnet.inference.writer`): with ``--realtime`` (and read-ahead) the sinks
of frame i run while the network completes frame i + 1, so the network is the only serial stage, and every promise
of the loop holds: outputs in order, the journal after the files, a sink's fault on a frame that frame's, Ctrl-C
and SIGTERM drain the writer, no thread left, back-pressure instead of an unbounded queue."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet.data.frames import Frame, IndexedSource
from semattnet.inference import Completion
from semattnet.inference.options import OutputSpec, RunOptions
from semattnet.inference.pipeline import check_frames
from semattnet.inference.sinks import DepthPngSink, Prediction, RunSink, Sink
from semattnet.inference.timing import StageTimes
from semattnet.inference.writer import WriteStage

SIZE = (8, 12)


class Frames(IndexedSource):
    """``n`` tiny frames with no stamps of their own (so 0.1 s apart at the sensor pace)."""

    def __init__(self, n: int) -> None:
        self.names = tuple(f"f{i:03d}" for i in range(n))

    def load(self, name: str) -> Frame:
        sparse = np.zeros(SIZE, np.float32)
        sparse[::2, ::2] = 4.0
        return Frame(name, np.full((*SIZE, 3), 90, np.uint8), sparse)

    def inputs(self) -> list[Path]:
        return []


class Sleepy:
    """A completer taking ``seconds`` a frame; ``interrupt``: the frame at which it raises ``interrupt_with``."""

    needs_semantic, palette, device = False, "cityscapes", "cpu"

    def __init__(self, seconds: float = 0.0, interrupt: int | None = None, interrupt_with: object = None) -> None:
        self.seconds, self.interrupt, self.interrupt_with, self.calls = seconds, interrupt, interrupt_with, 0

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        if self.calls == self.interrupt:
            if self.interrupt_with == "SIGTERM":
                # raised in this (the main) thread: os.kill may hand it to any thread of the process, and one CI run
                # of the whole suite (OpenVINO's and torch's worker threads alive) died of SIGSEGV right there
                signal.raise_signal(signal.SIGTERM)
                time.sleep(1)  # the handler raises here
            raise KeyboardInterrupt
        self.calls += 1
        time.sleep(self.seconds)
        return Completion(np.full(sparse.shape, 5.0, np.float32))


@dataclass
class Text(Sink):
    """``NAME.txt`` (the depth's role), ``seconds`` a frame; raises a frame fault on the frames ``bad``; records
    the order it wrote the frames in."""

    suffix: str = ".txt"
    seconds: float = 0.0
    bad: tuple[str, ...] = ()
    order: list[str] = field(default_factory=list)
    role: ClassVar[str] = "depth"

    def save(self, path: Path, pred: Prediction) -> None:
        time.sleep(self.seconds)
        self.order.append(pred.frame.name)
        path.write_text(f"{pred.stored.mean():.2f}")


@dataclass
class Faulty(Sink):
    """``NAME.flt``, refused (a frame fault, as the PLY's empty cloud) for the frames ``bad``."""

    suffix: str = ".flt"
    bad: tuple[str, ...] = ()

    def save(self, path: Path, pred: Prediction) -> None:
        if pred.frame.name in self.bad:
            raise InputError(f"{pred.frame.name}: the point cloud would be empty")
        path.write_text("ok")


class Recorder(RunSink):
    """A run output: the frames it is fed, in order."""

    def __init__(self) -> None:
        self.frames: list[str] = []

    def write(self, stage: Path, pred: Prediction) -> None:
        self.frames.append(pred.frame.name)


def _writers() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "semattnet-writer"]


def _paced_run(tmp: Path, n: int, speed: float, write_ahead: int | None) -> tuple[dict[str, int], StageTimes]:
    """``n`` frames paced ``speed`` times faster than 10 Hz; the network takes 0.8 of a period, the sink 0.5 (the
    writing a little more: the moves, the journal)."""
    period = 0.1 / speed
    timer = StageTimes()
    options = RunOptions(realtime=speed, write_ahead=write_ahead)
    plan = check_frames(Frames(n), [Text(seconds=0.5 * period)], tmp, options=options)
    run = plan.run(Sleepy(0.8 * period), timer=timer, log=lambda s: None)
    return run.counts, timer


@pytest.mark.parametrize(("n", "speed"), [(16, 2.0), pytest.param(50, 1.0, marks=pytest.mark.slow)])
def test_writing_beside_the_network_keeps_the_pace(tmp_path: Path, n: int, speed: float) -> None:
    """The network takes 0.8 of the sensor period and the writing over half: written beside the network, the
    frames keep the pace (no drops); written in line (``write_ahead=0``), each frame takes about 1.4 periods and
    about half are dropped. Drop counts with wide margins, never times."""
    piped, timer = _paced_run(tmp_path / "piped", n, speed, None)  # --realtime's default: the write stage
    serial, serial_timer = _paced_run(tmp_path / "serial", n, speed, 0)
    assert piped["dropped"] <= n // 8, piped  # 0 on 2 busy cores (load 12)
    assert serial["dropped"] >= n // 4, serial  # 7-8 of 16 there
    assert piped["done"] + piped["dropped"] == serial["done"] + serial["dropped"] == n
    table = timer.table()
    assert "beside the network (the writer thread)" in table and "serial path" in table
    assert timer.summary()["stages"]["network"].get("beside") is None
    assert "beside" not in serial_timer.summary()["stages"]["writing"]
    assert not _writers()


def test_order_and_the_journal_after_the_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Read ahead and written two frames behind: the files and the run output get the frames in order, and the
    journal records a frame only once all its files are in place."""
    text, recorder = Text(seconds=0.01), Recorder()
    source = Frames(8)
    plan = check_frames(source, [recorder, text, Faulty()], tmp_path, options=RunOptions(prefetch=2, write_ahead=2))
    recorded_with_files = []
    done = plan.journal.done

    def checked_done(name: str, files: list[str], *args: object, **kw: object) -> None:
        recorded_with_files.append(all((tmp_path / f).is_file() for f in files) and len(files) == 2)
        done(name, files, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(plan.journal, "done", checked_done)
    run = plan.run(Sleepy(), log=lambda s: None)
    names = list(source.names)
    assert text.order == recorder.frames == names
    assert recorded_with_files == [True] * len(names) and run.counts["done"] == len(names)
    assert not _writers()


@pytest.mark.parametrize("write_ahead", [0, 1])
def test_a_sink_fault_on_a_frame_is_that_frame_s(tmp_path: Path, write_ahead: int) -> None:
    """A sink that refuses one frame: that frame is skipped (its other files gone, the run outputs without it)
    and the run goes on; with ``on_error="stop"`` it is ``failed`` and stops the run, the frames before it kept."""
    text, recorder = Text(), Recorder()
    sinks = [recorder, text, Faulty(bad=("f002",))]  # the run output first: still fed after the files
    run = check_frames(Frames(5), sinks, tmp_path / "skip", options=RunOptions(write_ahead=write_ahead)).run(
        Sleepy(), log=lambda s: None
    )
    assert run.counts["skipped"] == 1 and run.counts["done"] == 4
    assert run.journal.frames["f002"]["reason"] == "f002: the point cloud would be empty"
    assert not (tmp_path / "skip" / "f002.txt").exists() and recorder.frames == ["f000", "f001", "f003", "f004"]
    options = RunOptions(on_error="stop", write_ahead=write_ahead)
    plan = check_frames(Frames(5), [Text(), Faulty(bad=("f002",))], tmp_path / "stop", options=options)
    with pytest.raises(InputError, match="f002: the point cloud would be empty"):
        plan.run(Sleepy(), log=lambda s: None)
    frames = json.loads((tmp_path / "stop" / "frames.json").read_text())["frames"]
    assert [f["status"] for f in frames] == ["done", "done", "failed", "pending", "pending"]
    assert not (tmp_path / "stop" / "f002.txt").exists() and not _writers()


#: A run stopped by SIGTERM at its fourth frame, in a fresh interpreter (what a terminated process is): the
#: suite's own process may hold OpenVINO's and torch's worker threads, and one full run of the suite died of
#: SIGSEGV when this test raised SIGTERM in it.
_TERMINATED = """
import sys
from pathlib import Path
from semattnet.inference.options import RunOptions
from semattnet.inference.pipeline import check_frames
from tests.inference.test_write_stage import Frames, Sleepy, Text
plan = check_frames(Frames(6), [Text(seconds=0.05)], Path(sys.argv[1]), options=RunOptions(write_ahead=2))
plan.run(Sleepy(interrupt=3, interrupt_with="SIGTERM"), log=lambda s: None)
"""


def _stopped_with_three_written(folder: Path) -> None:
    frames = json.loads((folder / "frames.json").read_text())["frames"]
    assert [f["status"] for f in frames] == ["done"] * 3 + ["pending"] * 3
    assert all((folder / f"f00{i}.txt").is_file() for i in range(3))


def test_ctrl_c_drains_the_writer(tmp_path: Path) -> None:
    """Ctrl-C while two frames wait to be written: they are written and journaled, then the run stops, no writer
    thread left, SIGTERM's default handling back."""
    plan = check_frames(Frames(6), [Text(seconds=0.05)], tmp_path, options=RunOptions(write_ahead=2))
    with pytest.raises(KeyboardInterrupt):
        plan.run(Sleepy(interrupt=3, interrupt_with="SIGINT"), log=lambda s: None)
    _stopped_with_three_written(tmp_path)
    assert not _writers() and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL


def test_sigterm_drains_the_writer_and_exits_143(tmp_path: Path) -> None:
    """SIGTERM while two frames wait to be written (a fresh process): they are written and journaled, then the
    process exits with status 143 (128 + SIGTERM), not killed at once."""
    root = Path(__file__).resolve().parents[2]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), str(root / "src"), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        [sys.executable, "-c", _TERMINATED, str(tmp_path)],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 128 + signal.SIGTERM, done.stderr[-2000:]
    _stopped_with_three_written(tmp_path)


def test_a_run_stopped_while_writing_resumes_exactly(tmp_path: Path) -> None:
    """Ctrl-C with frames in the writer, then ``resume``: the kept frames are not redone, the rest are, and the
    files and the run output (fed the kept frames in their place) equal those of an uninterrupted run."""
    options = RunOptions(prefetch=2, write_ahead=2)
    whole = Recorder()
    check_frames(Frames(6), [DepthPngSink(), whole], tmp_path / "whole", options=options).run(
        Sleepy(), log=lambda s: None
    )
    plan = check_frames(Frames(6), [DepthPngSink(), Text(seconds=0.05)], tmp_path / "cut", options=options)
    with pytest.raises(KeyboardInterrupt):
        plan.run(Sleepy(interrupt=3), log=lambda s: None)
    resumed, completer = Recorder(), Sleepy()
    spec = OutputSpec(resume=True)
    run = check_frames(Frames(6), [DepthPngSink(), Text(), resumed], tmp_path / "cut", spec, options).run(
        completer, log=lambda s: None
    )
    assert completer.calls == 3 and run.counts["done"] == 6  # the three written before the stop are kept
    assert resumed.frames == whole.frames == list(Frames(6).names)
    for name in Frames(6).names:
        assert (tmp_path / "cut" / f"{name}.png").read_bytes() == (tmp_path / "whole" / f"{name}.png").read_bytes()


def test_the_stage_waits_instead_of_queueing(tmp_path: Path) -> None:
    """``depth`` frames handed and not written: the next waits (back-pressure); notes never wait; tasks run in
    order; the first error stops the stage and is raised in the caller's thread."""
    gate, ran = threading.Event(), []

    def first() -> None:
        gate.wait(5)
        ran.append(1)

    with WriteStage(1) as stage:
        stage.submit(first)
        stage.submit(lambda: ran.append(2), frame=False)  # a note: at once
        handed = threading.Thread(target=stage.submit, args=(lambda: ran.append(3),))
        handed.start()
        handed.join(0.2)
        assert handed.is_alive() and ran == []  # waiting for the first frame to be written
        gate.set()
        handed.join(5)
        stage.drain()
    assert ran == [1, 2, 3] and stage.waited_s > 0.1 and not _writers()

    def fail() -> None:
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"), WriteStage(2) as stage:
        stage.submit(fail)
        stage.submit(lambda: ran.append(4), frame=False)
        stage.drain()
    assert ran == [1, 2, 3] and not _writers()
