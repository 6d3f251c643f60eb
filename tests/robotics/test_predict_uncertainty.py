"""``semattnet predict --uncertainty`` / ``--max-uncertainty`` on a bag: the files, the journal, the filtered PLY
and bag cloud, the bag's uncertainty topic, a resume byte for byte, and the one-line refusals."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import read_depth
from tests.robotics.test_long_runs import TOPICS, write_bag

pytest.importorskip("rosbags")

N, H, W = 3, 48, 80
NAMES = [f"{i:010d}" for i in range(N)]
K = np.array([[0.625 * W, 0, W / 2], [0, 0.625 * W, H / 2], [0, 0, 1.0]])  # write_bag's camera


def _predict(*args: object) -> Any:
    return CliRunner().invoke(main, ["predict", *map(str, args)])


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_bag(tmp_path_factory.mktemp("unc") / "in_mcap", N, H, W)


def _messages(path: Path) -> dict[str, list[Any]]:
    from semattnet.robotics.bags import open_bag

    with open_bag(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        out: dict[str, list[Any]] = {t: [] for t in types}
        for conn, _, raw in reader.messages():
            out[conn.topic].append(reader.deserialize(raw, conn.msgtype))
    assert types["/semattnet/uncertainty"] == "sensor_msgs/msg/Image"
    return out


def _float_image(msg: Any) -> np.ndarray:
    return np.frombuffer(np.asarray(msg.data, np.uint8).tobytes(), "<f4").reshape(msg.height, msg.width)


def _ply_xyz(path: Path) -> np.ndarray:
    from plyfile import PlyData

    v = PlyData.read(str(path))["vertex"]
    return np.column_stack([v["x"], v["y"], v["z"]])


def test_files_journal_ply_and_bag(bag: Path, tmp_path: Path) -> None:
    from semattnet.geometry import depth_to_points

    out, bag_out = tmp_path / "out", tmp_path / "pred_mcap"
    res = _predict(
        "--bag",
        bag,
        *TOPICS,
        "--method",
        "classical",
        "--out",
        out,
        "--npy",
        "--ply",
        "--uncertainty",
        "--max-uncertainty",
        "0.5",
        "--bag-out",
        bag_out,
    )
    assert res.exit_code == 0, res.output
    frames = {e["name"]: e for e in json.loads((out / "frames.json").read_text())["frames"]}
    msgs = _messages(bag_out)
    for i, name in enumerate(NAMES):
        assert {f"uncertainty/{name}.png", f"uncertainty/{name}.npy"} <= set(frames[name]["files"])
        depth, unc = read_depth(out / f"{name}.png"), read_depth(out / "uncertainty" / f"{name}.png")
        npy = np.load(out / "uncertainty" / f"{name}.npy")
        want = np.where(depth > 0, np.clip(np.round(npy.astype(np.float64) * 256), 1, 65535), 0)
        np.testing.assert_array_equal(np.round(unc * 256), want)  # metres * 256, 0 = none
        keep = (depth > 0) & (unc <= 0.5)
        assert 0 < keep.sum() < (depth > 0).sum()  # some dropped, some kept
        np.testing.assert_array_equal(_ply_xyz(out / f"{name}.ply"), depth_to_points(depth, K, mask=keep).xyz)
        u_msg, d_msg, p_msg = (msgs[f"/semattnet/{t}"][i] for t in ("uncertainty", "depth_image", "point_cloud"))
        assert u_msg.encoding == "32FC1" and u_msg.header == d_msg.header
        np.testing.assert_array_equal(_float_image(u_msg), np.where(unc > 0, unc, np.nan))
        np.testing.assert_array_equal(_float_image(d_msg), np.where(depth > 0, depth, np.nan))  # dense
        assert p_msg.width == keep.sum()
    assert (out / f"{NAMES[0]}.png").stat().st_size > 0 and len(list((out / "uncertainty").iterdir())) == 2 * N


def test_relative_limit_and_no_limit(bag: Path, tmp_path: Path) -> None:
    a, b = tmp_path / "rel", tmp_path / "all"
    res = _predict(
        "--bag", bag, *TOPICS, "--method", "classical", "--out", a, "--ply", "--uncertainty", "--max-uncertainty", "5%"
    )
    assert res.exit_code == 0, res.output
    res = _predict("--bag", bag, *TOPICS, "--method", "classical", "--out", b, "--ply")
    assert res.exit_code == 0, res.output
    assert not (b / "uncertainty").exists()
    name = NAMES[1]
    depth, unc = read_depth(a / f"{name}.png"), read_depth(a / "uncertainty" / f"{name}.png")
    keep = (depth > 0) & (unc <= 0.05 * depth.astype(np.float64))
    n_rel, n_all = len(_ply_xyz(a / f"{name}.ply")), len(_ply_xyz(b / f"{name}.ply"))
    assert n_rel == keep.sum() < n_all == (depth > 0).sum()


def _tree(root: Path) -> dict[str, bytes]:
    skip = {"frames.json", "latency.json"}
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and p.name not in skip
    }


def test_resume_keeps_and_redoes_the_uncertainty_files(bag: Path, tmp_path: Path) -> None:
    """A resumed run (one frame's uncertainty PNG lost, the bag not written) equals an uninterrupted one."""
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    opts = [
        "--bag",
        bag,
        *TOPICS,
        "--method",
        "classical",
        "--npy",
        "--ply",
        "--uncertainty",
        "--max-uncertainty",
        "1.5",
    ]
    assert _predict(*opts, "--out", whole, "--bag-out", tmp_path / "w" / "b_mcap").exit_code == 0
    assert _predict(*opts, "--out", cut, "--bag-out", tmp_path / "c" / "b_mcap").exit_code == 0
    (cut / "uncertainty" / f"{NAMES[1]}.png").unlink()
    shutil.rmtree(tmp_path / "c" / "b_mcap")
    res = _predict(*opts, "--out", cut, "--bag-out", tmp_path / "c" / "b_mcap", "--resume")
    assert res.exit_code == 0, res.output
    assert f"resuming: {N - 1} of {N} frame(s) already done" in res.output
    assert _tree(cut) == _tree(whole) and len(_tree(cut)) == 6 * N
    assert _tree(tmp_path / "c" / "b_mcap") == _tree(tmp_path / "w" / "b_mcap")
    res = _predict(*opts[:-1], "2", "--out", cut, "--bag-out", tmp_path / "c" / "b_mcap", "--resume")
    assert res.exit_code == 1 and "--max-uncertainty was '1.5' in the first run, now '2'" in res.output, res.output


@pytest.mark.parametrize("value", ["abc", "0", "-1", "300", "1500%", "nan", "0%"])
def test_bad_limits_are_refused_in_one_line(bag: Path, tmp_path: Path, value: str) -> None:
    res = _predict(
        "--bag",
        bag,
        *TOPICS,
        "--method",
        "classical",
        "--out",
        tmp_path / "o",
        "--ply",
        "--uncertainty",
        "--max-uncertainty",
        value,
    )
    assert res.exit_code == 2
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert errors == [
        f"Error: Invalid value for '--max-uncertainty': expected metres in (0, 255] (e.g. 0.5) or a "
        f"percentage of the depth in (0, 1000%] (e.g. 5%), got {value!r}"
    ], res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (
            [],
            "--max-uncertainty only mean(s) something with --ply, --panel (with --kitti-raw or --bag), --bag-out, "
            "--rerun or --live",
        ),
        (["--bag-out", "B"], "--max-uncertainty with --bag-out or --rerun needs --uncertainty"),
    ],
)
def test_limit_without_a_cloud_or_a_stored_uncertainty_is_refused(
    bag: Path, tmp_path: Path, args: list[str], says: str
) -> None:
    args = [str(tmp_path / a) if a == "B" else a for a in args]
    res = _predict(
        "--bag", bag, *TOPICS, "--method", "classical", "--out", tmp_path / "o", "--max-uncertainty", "1", *args
    )
    assert res.exit_code == 2 and says in res.output, res.output
    assert not (tmp_path / "o").exists()


def test_rerun_recording_has_an_uncertainty_layer(bag: Path, tmp_path: Path) -> None:
    pytest.importorskip("rerun")
    from semattnet.robotics.rerun import ENTITIES, read_rrd_frames

    rrd = tmp_path / "run.rrd"
    res = _predict(
        "--bag",
        bag,
        *TOPICS,
        "--method",
        "classical",
        "--out",
        tmp_path / "o",
        "--uncertainty",
        "--rerun",
        rrd,
        "--max-uncertainty",
        "10%",
    )
    assert res.exit_code == 0, res.output
    frames = read_rrd_frames(rrd)
    assert len(frames[ENTITIES["uncertainty"]]) == N and frames[ENTITIES["uncertainty"]] == frames[ENTITIES["depth"]]
    res = _predict(
        "--bag", bag, *TOPICS, "--method", "classical", "--out", tmp_path / "p", "--rerun", tmp_path / "plain.rrd"
    )
    assert res.exit_code == 0, res.output
    assert ENTITIES["uncertainty"] not in read_rrd_frames(tmp_path / "plain.rrd")
