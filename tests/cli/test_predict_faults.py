"""``semattnet predict`` on folders of frames and a KITTI raw drive with bad frames among good ones: the good
ones are done, each bad one is skipped with one line naming it and why, ``frames.json`` records every frame,
and the exit status is 3."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import write_depth, write_image


def _predict(*args: object) -> Any:
    return CliRunner().invoke(main, ["predict", *map(str, args)])


def _statuses(out: Path) -> dict[str, tuple[str, str]]:
    doc = json.loads((out / "frames.json").read_text())
    assert doc["complete"] is True
    return {e["name"]: (e["status"], e.get("reason", "")) for e in doc["frames"]}


def _skip_line(output: str, name: str) -> str:
    lines = [ln for ln in output.splitlines() if ln.startswith(f"{name}: skipped: ")]
    assert len(lines) == 1, (name, output)
    return lines[0]


def test_folder_with_bad_frames(tmp_path: Path) -> None:
    """f2: an all-zero sparse map, f3: a sparse 'PNG' that is not one, f4: an image without a sparse map."""
    rgb, sparse, clean = tmp_path / "rgb", tmp_path / "sparse", tmp_path / "clean"
    for d in (rgb, sparse, clean):
        d.mkdir()
    for i in range(6):
        rng = np.random.default_rng(i)
        write_image(rgb / f"f{i}.png", rng.integers(0, 256, (32, 48, 3), dtype=np.uint8))
        depth = np.zeros((32, 48), np.float32)
        hit = rng.random((32, 48)) < 0.1
        depth[hit] = rng.uniform(1, 50, hit.sum())
        write_depth(clean / f"f{i}.png", depth)
        if i != 4:
            write_depth(sparse / f"f{i}.png", np.zeros_like(depth) if i == 2 else depth)
    (sparse / "f3.png").write_bytes(b"not a png at all")
    out = tmp_path / "out"
    res = _predict("--rgb", rgb, "--sparse", sparse, "--method", "classical", "--out", out)
    assert res.exit_code == 3, res.output
    reasons = {
        "f2": "f2.png: sparse has no valid depth point",
        "f3": "f3.png: not a readable PNG",
        "f4": "f4.png: PNG file not found",
    }
    for name, reason in reasons.items():
        assert reason in _skip_line(res.output, name), res.output
    assert "6 frame(s): 3 done, 3 skipped" in res.output
    journal = _statuses(out)
    assert {n: s for n, (s, _) in journal.items()} == {
        "f0": "done",
        "f1": "done",
        "f2": "skipped",
        "f3": "skipped",
        "f4": "skipped",
        "f5": "done",
    }
    assert all(reasons[n] in journal[n][1] for n in reasons)
    want = tmp_path / "want"  # the good frames: as a run over the good frames alone does them
    res = _predict("--rgb", rgb, "--sparse", clean, "--method", "classical", "--out", want)
    assert res.exit_code == 0, res.output
    for name in ("f0", "f1", "f5"):
        assert (out / f"{name}.png").read_bytes() == (want / f"{name}.png").read_bytes()
    assert not (out / "f2.png").exists() and not (out / "f3.png").exists() and not (out / "f4.png").exists()


def test_kitti_raw_drive_with_a_bad_scan(tmp_path: Path) -> None:
    from tests.inference._raw_sample import three_frame_drive

    drive = three_frame_drive(tmp_path)  # frames 5, 6, 7
    scan = drive / "velodyne_points" / "data" / "0000000006.bin"
    scan.write_bytes(scan.read_bytes()[:1005])  # not a whole number of points
    out = tmp_path / "out"
    res = _predict("--kitti-raw", drive, "--method", "classical", "--out", out)
    assert res.exit_code == 3, res.output
    line = _skip_line(res.output, "0000000006")
    assert "0000000006.bin: 1005 bytes is not a multiple of 16" in line, line
    assert {n: s for n, (s, _) in _statuses(out).items()} == {
        "0000000005": "done",
        "0000000006": "skipped",
        "0000000007": "done",
    }
    assert (out / "0000000005.png").read_bytes() == (out / "0000000007.png").read_bytes()
    assert sorted(p.name for p in out.glob("*.png")) == [
        "0000000005.png",
        "0000000005_color.png",
        "0000000007.png",
        "0000000007_color.png",
    ]
