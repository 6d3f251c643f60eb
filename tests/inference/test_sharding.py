"""Frames split over torchrun processes: the helpers in one process, and ``predict`` under torchrun
with two CPU processes writing exactly the files of one process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from semattnet._utils.outputs import STAGE_PREFIX, OutputError
from semattnet.data.io import write_depth, write_image
from semattnet.inference.sharding import agree, gather_rows, on_main, rank_log, shard, shared_stage

TIMEOUT = 240


# ----------------------------------------------------------------------------- one process


def test_helpers_are_plain_calls_in_one_process() -> None:
    assert shard(list("abcde")) == list("abcde")
    assert agree(lambda a, b: a + b, 1, b=2) == 3 and on_main(max, [1, 5, 2]) == 5
    with pytest.raises(ValueError, match="boom"):
        agree(lambda: (_ for _ in ()).throw(ValueError("boom")))
    assert gather_rows([{"k": 2}, {"k": 1}], key=lambda r: r["k"]) == [{"k": 1}, {"k": 2}]
    lines: list[str] = []
    rank_log(lines.append)("x")
    assert lines == ["x"]


def test_shared_stage_moves_everything_or_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with shared_stage(out, expected=["a.txt", "sub/b.txt"]) as stage:
        (stage / "a.txt").write_text("a")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.txt").write_text("b")
    assert (out / "a.txt").read_text() == "a" and (out / "sub" / "b.txt").read_text() == "b"
    with pytest.raises(OutputError, match=r"1 output file\(s\) missing .*c\.txt"):
        with shared_stage(out, overwrite=True, expected=["a.txt", "c.txt"]) as stage:
            (stage / "a.txt").write_text("new")
    with pytest.raises(RuntimeError, match="frame failed"):
        with shared_stage(out, overwrite=True) as stage:
            (stage / "a.txt").write_text("new")
            raise RuntimeError("frame failed")
    assert (out / "a.txt").read_text() == "a"  # unchanged by both failures
    assert not list(out.glob(f"{STAGE_PREFIX}*"))


# ----------------------------------------------------------------------------- torchrun


def _frames(root: Path, count: int = 6) -> tuple[Path, Path]:
    rng = np.random.default_rng(0)
    rgb, sparse = root / "rgb", root / "sparse"
    for i in range(count):
        write_image(rgb / f"f{i}.png", rng.integers(0, 255, (64, 96, 3), dtype=np.uint8))
        d = np.zeros((64, 96), np.float32)
        d[20::3, ::4] = rng.uniform(2, 60, d[20::3, ::4].shape)
        write_depth(sparse / f"f{i}.png", d)
    return rgb, sparse


def _env() -> dict[str, str]:
    return os.environ | {"OMP_NUM_THREADS": "1"}


def cli(*args: object, nproc: int = 1, logs: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``semattnet ARGS`` in one process, or under torchrun with ``nproc`` CPU processes (their
    stdout/stderr in ``logs``)."""
    run = [sys.executable, "-m", "semattnet.cli"]
    if nproc > 1:
        run = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", str(nproc)]
        run += ["--log-dir", str(logs), "--redirects", "3", "-m", "semattnet.cli"]  # type: ignore[list-item]
    return subprocess.run([*run, *map(str, args)], capture_output=True, text=True, env=_env(), timeout=TIMEOUT)


def rank_logs(logs: Path, stream: str = "stderr") -> list[str]:
    """Each rank's ``stream`` of the (one) torchrun launch logged in ``logs``, by local rank."""
    files = sorted(logs.glob(f"*/attempt_0/*/{stream}.log"), key=lambda p: int(p.parent.name))
    return [f.read_text() for f in files]


def tree_bytes(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def assert_one_line_error(res: subprocess.CompletedProcess[str], logs: Path, ranks: int, match: str) -> None:
    """Every rank stopped with the same single line naming ``match`` and no traceback."""
    assert res.returncode != 0
    errs = rank_logs(logs)
    assert len(errs) == ranks, errs
    for err in errs:
        assert "Traceback" not in err, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("Error: ") and match in lines[0], err
    assert len(set(errs)) == 1


def _latencies(*trees: dict[str, bytes]) -> None:
    """Each run wrote its per-stage latency table (``latency.json``) and its journal (``frames.json``, with each
    frame's times); taken out of the byte comparison, the journals' statuses and files compared instead."""
    import json

    journals = []
    for tree in trees:
        table = json.loads(tree.pop("latency.json"))
        assert table["frames"] > 0, table
        doc = json.loads(tree.pop("frames.json"))
        assert doc["complete"] and not [k for k in tree if k.startswith(".frames.rank")], doc
        journals.append([(e["name"], e["status"], e.get("files")) for e in doc["frames"]])
    assert all(j == journals[0] for j in journals), journals


@pytest.mark.slow  # ~15 s: two processes; the sharding itself is tested in one process above
def test_predict_two_processes_equals_one(tmp_path: Path) -> None:
    rgb, sparse = _frames(tmp_path)
    common = ("predict", "--method", "classical", "--rgb", rgb, "--sparse", sparse, "--npy")
    one = cli(*common, "--out", tmp_path / "one")
    assert one.returncode == 0, one.stderr
    res = cli(*common, "--out", tmp_path / "two", nproc=2, logs=tmp_path / "logs")
    assert res.returncode == 0, res.stderr[-3000:]
    a, b = tree_bytes(tmp_path / "one"), tree_bytes(tmp_path / "two")
    _latencies(a, b)  # timings differ run to run; every other byte is equal
    assert len(a) == 6 * 3 and a.keys() == b.keys()
    assert all(a[k] == b[k] for k in a), [k for k in a if a[k] != b[k]]
    out0, out1 = rank_logs(tmp_path / "logs", "stdout")
    assert out0.count("[rank 0/2] f") == 3 and "f0:" in out0 and "f2:" in out0 and "f4:" in out0
    assert out1.count("[rank 1/2] f") == 3 and "f1:" in out1 and "f5:" in out1

    again = cli(*common, "--out", tmp_path / "two", nproc=2, logs=tmp_path / "logs2")
    assert_one_line_error(again, tmp_path / "logs2", 2, "exists")
    after = tree_bytes(tmp_path / "two")
    _latencies(after)
    assert after == b  # untouched, no stage folder left behind


@pytest.mark.slow  # ~8 s; one two-process run stays in the default suite
def test_predict_bad_frame_on_one_rank_stops_all(tmp_path: Path) -> None:
    rgb, sparse = _frames(tmp_path, count=4)
    (sparse / "f3.png").write_bytes(b"not a png")  # rank 1's frame
    common = ("predict", "--method", "classical", "--rgb", rgb, "--sparse", sparse)
    res = cli(*common, "--on-error", "stop", "--out", tmp_path / "out", nproc=2, logs=tmp_path / "logs")
    assert_one_line_error(res, tmp_path / "logs", 2, "f3.png")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    # skipped (the default): the other frames done, f3 named, one frames.json merged from both processes
    res = cli(*common, "--out", tmp_path / "skip", nproc=2, logs=tmp_path / "logs2")
    assert res.returncode == 0, res.stderr[-3000:]  # torchrun takes a non-zero status for a crash
    doc = json.loads((tmp_path / "skip" / "frames.json").read_text())
    assert [(e["name"], e["status"]) for e in doc["frames"]] == [
        ("f0", "done"),
        ("f1", "done"),
        ("f2", "done"),
        ("f3", "skipped"),
    ]
    assert "f3.png" in doc["frames"][3]["reason"] and doc["complete"]
    assert sorted(p.name for p in (tmp_path / "skip").iterdir() if p.name.startswith(".")) == []


@pytest.mark.slow  # ~8 s; the folder case (test_predict_two_processes_equals_one) runs by default
def test_predict_kitti_raw_two_processes_equals_one(tmp_path: Path) -> None:
    from tests.inference._raw_sample import three_frame_drive

    drive = three_frame_drive(tmp_path)  # frames 5, 6, 7
    common = ("predict", "--kitti-raw", drive, "--method", "classical", "--ply", "--top-crop", "100")
    one = cli(*common, "--out", tmp_path / "one")
    assert one.returncode == 0, one.stderr[-3000:]
    res = cli(*common, "--out", tmp_path / "two", nproc=2, logs=tmp_path / "logs")
    assert res.returncode == 0, res.stderr[-3000:]
    a, b = tree_bytes(tmp_path / "one"), tree_bytes(tmp_path / "two")
    _latencies(a, b)
    assert len(a) == 3 * 3 and a == b
    out0, out1 = rank_logs(tmp_path / "logs", "stdout")
    assert "[rank 0/2] 0000000005" in out0 and "[rank 0/2] 0000000007" in out0 and "[rank 1/2] 0000000006" in out1
