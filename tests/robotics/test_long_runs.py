"""A long ``semattnet predict`` run survives its bad frames, its kills and a slow completer (bags).

* bad frames among good ones are skipped and named, the good ones done as a clean bag does them, every frame
  journaled in ``frames.json``, exit 3; ``--on-error stop`` keeps the frames done before the first bad one;
* a run killed with SIGKILL is resumed with ``--resume`` into the outputs of an uninterrupted run, byte for
  byte; a resume with other options, one without a journal and a rerun over a journal are one-line refusals;
* ``--realtime`` drops the frames that come while the completer is busy (the newest wins), counts them in
  ``frames.json`` and ``latency.json`` and exits 4.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.baselines.classical import ClassicalCompleter
from semattnet.cli import main
from tests.robotics import _faulty_bag as fb
from tests.robotics._faulty_bag import FAULTS, GOOD, IMAGE_TOPIC, N_FRAMES, POINTS_TOPIC, write_faulty_bag

T0, T_CAM_LIDAR = fb.T0, fb.T_CAM_LIDAR

pytest.importorskip("rosbags")

TOPICS = ["--image-topic", IMAGE_TOPIC, "--points-topic", POINTS_TOPIC]
DEPTH_TOPIC = "/semattnet/depth_image"
#: Frames of the run that is killed and resumed (128x192, about 20 ms each).
N_LONG = 40


def _predict(*args: object) -> Any:
    return CliRunner().invoke(main, ["predict", *map(str, args)])


def _journal(out: Path) -> dict[str, Any]:
    return json.loads((out / "frames.json").read_text())


def _statuses(doc: dict[str, Any]) -> dict[str, str]:
    return {e["name"]: e["status"] for e in doc["frames"]}


def _depth_messages(bag: Path) -> list[tuple[int, np.ndarray]]:
    """(header stamp ns, depth) of every depth image of a ``--bag-out`` bag, in order."""
    from semattnet.robotics.bags import open_bag

    with open_bag(bag) as reader:
        conns = [c for c in reader.connections if c.topic == DEPTH_TOPIC]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conns)]
    return [
        (
            m.header.stamp.sec * 10**9 + m.header.stamp.nanosec,
            np.frombuffer(np.asarray(m.data, np.uint8).tobytes(), "<f4").reshape(m.height, m.width),
        )
        for m in msgs
    ]


def write_bag(path: Path, n: int, h: int, w: int, fmt: str = "mcap", gaps_s: dict[int, float] | None = None) -> Path:
    """A clean bag of ``n`` random frames (h x w camera, a 2000-point scan 2 ms after each image, 0.1 s apart;
    ``gaps_s``: frame index -> seconds after the frame before it instead) on the topics of
    :mod:`tests.robotics._faulty_bag`."""
    from semattnet.robotics.bags import CameraInfoData, MessageWriter
    from semattnet.robotics.bags.encode import camera_info_message, image_message, pointcloud2_message, tf_message

    K = np.array([[0.625 * w, 0, w / 2], [0, 0.625 * w, h / 2], [0, 0, 1.0]])
    info = CameraInfoData(w, h, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam")
    with MessageWriter(path, fmt) as out:
        out.write("/tf_static", T0, tf_message(out.ts, [("cam", "lidar", T_CAM_LIDAR)], T0))
        t = T0
        for i in range(n):
            t, rng = t + (0 if i == 0 else round((gaps_s or {}).get(i, 0.1) * 1e9)), np.random.default_rng(i)
            rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
            out.write(IMAGE_TOPIC, t, image_message(out.ts, rgb, t, "cam"))
            out.write("/cam/camera_info", t, camera_info_message(out.ts, info, t, "cam"))
            pts = np.column_stack(
                [rng.uniform(3, 30, 2000), rng.uniform(-6, 6, 2000), rng.uniform(-1.5, 1, 2000)]
            ).astype(np.float32)
            cols = {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}
            out.write(POINTS_TOPIC, t + 2 * 10**6, pointcloud2_message(out.ts, cols, t + 2 * 10**6, "lidar"))
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The faulty MCAP bag, its clean twin (and the clean run's outputs) and one bad only at frame 1 (load)."""
    root = tmp_path_factory.mktemp("long")
    out: dict[str, Any] = {"faulty": write_faulty_bag(root / "faulty_mcap", "mcap")}
    out["clean"] = write_faulty_bag(root / "clean_mcap", "mcap", bad=())
    out["frame1"] = write_faulty_bag(root / "frame1_mcap", "mcap", bad=("empty_scan",))
    out["clean_out"] = root / "clean_out"
    res = _predict("--bag", out["clean"].path, *TOPICS, "--method", "classical", "--out", out["clean_out"])
    assert res.exit_code == 0, res.output
    return out


def test_bad_frames_are_skipped_named_and_journaled(bags: dict[str, Any], tmp_path: Path) -> None:
    from PIL import Image

    faulty, out, bag_out, rrd = bags["faulty"], tmp_path / "out", tmp_path / "pred_mcap", tmp_path / "run.rrd"
    res = _predict(
        "--bag", faulty.path, *TOPICS, "--method", "classical", "--out", out, "--bag-out", bag_out, "--rerun", rrd
    )
    assert res.exit_code == 3, res.output
    names = [f"{i:010d}" for i in range(N_FRAMES)]
    for i, reason in faulty.bad.items():  # one line per bad frame, naming it and why
        lines = [ln for ln in res.output.splitlines() if ln.startswith(f"{names[i]}: skipped: ")]
        assert len(lines) == 1 and reason in lines[0], (i, res.output)
    for i in GOOD:  # the good frames: as the clean bag does them
        for suffix in (".png", "_color.png"):
            got = (out / f"{names[i]}{suffix}").read_bytes()
            assert got == (bags["clean_out"] / f"{names[i]}{suffix}").read_bytes(), (i, suffix)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [f"{names[i]}{s}" for i in GOOD for s in (".png", "_color.png")] + ["frames.json", "latency.json"]
    )
    doc = _journal(out)
    assert doc["complete"] is True and doc["counts"]["done"] == len(GOOD) and doc["counts"]["skipped"] == 5
    for i, entry in enumerate(doc["frames"]):
        assert entry["name"] == names[i]
        if i in faulty.bad:
            assert entry["status"] == "skipped" and faulty.bad[i] in entry["reason"], entry
        else:
            assert entry["status"] == "done" and set(entry["files"]) == {f"{names[i]}.png", f"{names[i]}_color.png"}
    assert "5 skipped" in res.output and "sensor period of 100.0 ms" in res.output  # from every frame's stamp
    for _, reason in FAULTS.values():  # the summary groups the reasons, each readable
        kind = reason.split(" (", 1)[0].rsplit(": ", 1)[-1]
        assert f"skipped x1: {kind}" in res.output, (kind, res.output)
    depths = _depth_messages(bag_out)  # the bag holds exactly the frames done
    assert [t for t, _ in depths] == [T0 + i * 10**8 for i in GOOD]
    png = np.asarray(Image.open(out / f"{names[GOOD[1]]}.png")).astype(np.float32)
    depth = depths[1][1]
    assert np.array_equal(np.isnan(depth), png == 0) and np.array_equal(depth[png > 0], png[png > 0] / 256.0)
    assert rrd.is_file() and rrd.stat().st_size > 0
    pytest.importorskip("rerun")
    from semattnet.robotics.rerun import ENTITIES, read_rrd_frames

    assert read_rrd_frames(rrd)[ENTITIES["depth"]] == [T0 + i * 10**8 for i in GOOD]


def test_on_error_stop_keeps_the_frames_done_before_the_bad_one(bags: dict[str, Any], tmp_path: Path) -> None:
    out, bag_out, rrd = tmp_path / "out", tmp_path / "pred_mcap", tmp_path / "run.rrd"
    args = [*TOPICS, "--method", "classical", "--out", out, "--bag-out", bag_out, "--rerun", rrd, "--on-error", "stop"]
    res = _predict("--bag", bags["frame1"].path, *args)  # frame 1's scan fails when projected (after the check)
    assert res.exit_code == 1, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1 and "image 1: " in errors[0] and FAULTS["empty_scan"][1] in errors[0], res.output
    assert "Traceback" not in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no bag, no recording
    assert sorted(p.name for p in out.iterdir()) == ["0000000000.png", "0000000000_color.png", "frames.json"]
    doc = _journal(out)
    assert doc["complete"] is False
    assert _statuses(doc) == {
        "0000000000": "done",
        "0000000001": "failed",
        **{f"{i:010d}": "pending" for i in range(2, N_FRAMES)},
    }
    assert (out / "0000000000.png").read_bytes() == (bags["clean_out"] / "0000000000.png").read_bytes()
    # every fault: the inputs are checked before any work, so the first one the check finds stops it at once
    args[args.index(out)] = tmp_path / "out2"
    res = _predict("--bag", bags["faulty"].path, *args)
    assert res.exit_code == 1 and FAULTS["skew"][1] in res.output, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def _tree(root: Path) -> dict[str, bytes]:
    skip = {"frames.json", "latency.json"}  # times: compared by statuses and files
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and p.name not in skip
    }


def _kill_after(cmd: list[str], out: Path, done: int) -> None:
    """Start ``semattnet CMD`` and SIGKILL it once ``out/frames.json`` records ``done`` frames done."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "semattnet.cli", *cmd], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                if _journal(out)["counts"]["done"] >= done:
                    break
            except (OSError, ValueError, KeyError):
                pass
            time.sleep(0.002)
        assert proc.poll() is None, f"the run ended before it could be killed: {proc.stderr.read()[-2000:]!r}"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL


def test_killed_run_resumes_into_the_uninterrupted_outputs(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "long_mcap", N_LONG, 128, 192)
    killed, whole = tmp_path / "killed", tmp_path / "whole"
    opts = ["--bag", str(bag), *TOPICS, "--method", "classical", "--npy"]
    _kill_after(["predict", *opts, "--out", str(killed), "--bag-out", str(tmp_path / "k" / "pred_mcap")], killed, 2)
    doc = _journal(killed)
    assert doc["complete"] is False and doc["counts"]["pending"] > 0 and doc["counts"]["done"] >= 2, doc["counts"]
    assert not (tmp_path / "k" / "pred_mcap").exists()  # the run outputs come at the end
    kept = doc["counts"]["done"]
    before = {p.name: p.stat().st_mtime_ns for p in killed.iterdir() if p.name != ".semattnet.lock"}  # killed: stale
    res = _predict(*opts, "--out", killed, "--bag-out", tmp_path / "k" / "pred_mcap", "--max-depth", 40, "--resume")
    assert res.exit_code == 1 and "--max-depth was 80.0" in res.output, res.output
    assert len(res.output.strip().splitlines()) <= 2, res.output  # the pairing report, then the error
    assert {p.name: p.stat().st_mtime_ns for p in killed.iterdir()} == before  # nothing changed in OUT (lock gone)
    res = _predict(*opts, "--out", killed, "--bag-out", tmp_path / "k" / "pred_mcap")
    assert res.exit_code == 1 and "--resume" in res.output and len(res.output.strip().splitlines()) <= 2, res.output
    res = _predict(*opts, "--out", killed, "--bag-out", tmp_path / "k" / "pred_mcap", "--resume")
    assert res.exit_code == 0, res.output
    assert f"resuming: {kept} of {N_LONG} frame(s) already done" in res.output
    res = _predict(*opts, "--out", whole, "--bag-out", tmp_path / "w" / "pred_mcap")
    assert res.exit_code == 0, res.output
    a, b = _tree(killed), _tree(whole)
    assert len(a) == 3 * N_LONG and a == b
    assert _tree(tmp_path / "k" / "pred_mcap") == _tree(tmp_path / "w" / "pred_mcap")  # one name: metadata.yaml says it
    assert os.listdir(tmp_path / "k") == ["pred_mcap"]  # what the killed run staged beside it is gone
    ja, jb = _journal(killed), _journal(whole)
    assert ja["complete"] is jb["complete"] is True
    assert [(e["name"], e["status"], e["files"]) for e in ja["frames"]] == [
        (e["name"], e["status"], e["files"]) for e in jb["frames"]
    ]
    la, lb = (json.loads((d / "latency.json").read_text()) for d in (killed, whole))
    assert la["frames"] == lb["frames"] == N_LONG


def test_resume_without_a_journal_is_refused(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    bag = write_bag(tmp_path / "b_mcap", 2, 32, 48)
    for args in (["--out", tmp_path / "empty", "--resume"], ["--resume", tmp_path / "empty"]):
        res = _predict("--bag", bag, *TOPICS, "--method", "classical", *args)
        assert res.exit_code == 1 and "no frames.json to resume from" in res.output, res.output
        assert len(res.output.strip().splitlines()) <= 2 and not any((tmp_path / "empty").iterdir())


class _Slow(ClassicalCompleter):
    """The classical completer, ``seconds`` slower per frame."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Any:
        time.sleep(self.seconds)
        return super().__call__(rgb, sparse, semantic)


def test_realtime_drops_the_frames_that_come_while_busy(tmp_path: Path) -> None:
    from semattnet.inference.pipeline import EXIT_DROPPED, RunOptions, check_frames
    from semattnet.inference.sinks import LatencySink, default_sinks
    from semattnet.inference.timing import StageTimes
    from semattnet.robotics import BagSource

    bag, out = write_bag(tmp_path / "b_mcap", 8, 32, 48), tmp_path / "out"
    source, timer = BagSource(bag, IMAGE_TOPIC, POINTS_TOPIC), StageTimes()
    sinks = [*default_sinks(), LatencySink(timer=timer)]
    plan = check_frames(source, sinks, out, options=RunOptions(realtime=20.0))
    run = plan.run(_Slow(0.05), timer=timer, log=lambda _: None)
    # frames 5 ms apart (35 ms in all), 50 ms a frame: whichever frame is taken first, every later one but the
    # last comes while it is completed and is replaced by the next; the newest is never replaced. (Which frame is
    # taken first depends on when the loop's thread starts: on a loaded machine frame 1 may have replaced frame 0.)
    doc = _journal(out)
    statuses = _statuses(doc)
    dropped = [n for n, s in statuses.items() if s == "dropped"]
    assert statuses[source.names[-1]] == "done" and list(statuses.values()).count("done") <= 3, statuses
    assert len(dropped) >= 5 and set(statuses.values()) == {"done", "dropped"}
    assert run.exit_code == EXIT_DROPPED and doc["counts"]["dropped"] == len(dropped)
    assert all("arrived while the completer was busy" in e["reason"] for e in doc["frames"] if e["name"] in dropped)
    latency = json.loads((out / "latency.json").read_text())
    assert latency["not_done"] == {"dropped": len(dropped), "skipped": 0}
    assert latency["frames"] == 8 - len(dropped)
    assert latency["queue_most"] is not None and latency["queue_most"] <= 2, latency
    assert f"not completed: {len(dropped)} dropped; at most" in timer.table()


def test_realtime_cli(tmp_path: Path) -> None:
    bag, out = write_bag(tmp_path / "b_mcap", 8, 32, 48), tmp_path / "out"
    res = _predict("--bag", bag, *TOPICS, "--method", "classical", "--out", out, "--realtime", "--speed", 1000)
    counts = _journal(out)["counts"]
    assert res.exit_code == (4 if counts["dropped"] else 0), res.output
    assert counts["done"] + counts["dropped"] == 8 and counts["skipped"] == 0
    assert _statuses(_journal(out))["0000000007"] == "done"
    assert f"8 frame(s): {counts['done']} done" in res.output
    assert (f"{counts['dropped']} dropped" in res.output) == bool(counts["dropped"])
    res = _predict("--bag", bag, *TOPICS, "--method", "classical", "--out", tmp_path / "o2", "--speed", 2)
    assert res.exit_code == 2 and "--speed needs --realtime" in res.output
