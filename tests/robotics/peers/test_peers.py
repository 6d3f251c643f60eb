"""The ROS 2 node against DDS implementations that are not ours, each run in its own loopback-only network
namespace: a Cyclone DDS C subscriber and a Fast DDS C++ camera publisher and subscriber (``conftest.py``).
The depth they receive equals ``predict --bag``'s float depth (``--npy``) on the same frames (classical method:
exact), with the input's stamp and frame id. ``pytest -m ros_peers`` (after ``bash scripts/setup-ros-peers.sh``)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.geometry import RigCalibration, make_T
from semattnet.robotics.bags import BagTopics, SensorRecord, write_sensor_bag

from ._netns import HERE, run_isolated

pytestmark = pytest.mark.ros_peers

H, W = 48, 64
K = np.array([[40.0, 0, 31.5], [0, 40.0, 23.5], [0, 0, 1]])
T_CAM_LIDAR = make_T(np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]]), np.array([0.02, -0.08, -0.05]))
T0, STEP, FRAMES = 1_700_000_000_250_000_000, 100_000_000, 3
OUT_TOPIC = "/semattnet/output/depth_image"
TOPICS = BagTopics()


def _record(i: int, rng: np.random.Generator) -> SensorRecord:
    """A wall 8 + i m ahead with a box at 4 m, seen by a 16-beam LiDAR; a textured image."""
    az, el = np.meshgrid(np.radians(np.linspace(-40, 40, 120)), np.radians(np.linspace(-15, 15, 16)))
    r = np.where((np.abs(az) < 0.2) & (el < 0.05), 4.0, 8.0 + i) / np.cos(az) / np.cos(el)
    pts = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], -1).reshape(-1, 3)
    image = rng.integers(0, 255, (H, W, 3), dtype=np.uint8)
    return SensorRecord(image, pts.astype(np.float32), T0 + i * STEP, T0 + i * STEP + 2_000_000)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The bag, its rig file, the frames as raw files (for the Fast DDS camera) and ``predict --bag --npy``'s float
    depth per stamp (with the bag's CameraInfo and /tf_static, and with the rig)."""
    root = tmp_path_factory.mktemp("recorded")
    rng = np.random.default_rng(5)
    records = [_record(i, rng) for i in range(FRAMES)]
    bag = write_sensor_bag(root / "drive_mcap", records, RigCalibration(K, T_CAM_LIDAR, (W, H))).path
    rig = root / "rig.json"
    rig.write_text(json.dumps({"K": K.tolist(), "T_cam_lidar": T_CAM_LIDAR.tolist(), "image_size": [W, H]}))
    raw = root / "raw"
    raw.mkdir()
    lines = [f"{W} {H} {FRAMES} {TOPICS.camera_frame} {TOPICS.lidar_frame}"]
    for i, rec in enumerate(records):
        (raw / f"rgb_{i}.bin").write_bytes(rec.image.tobytes())
        (raw / f"points_{i}.bin").write_bytes(rec.points.astype("<f4").tobytes())
        lines.append(f"{rec.image_stamp_ns} {len(rec.points)}")
    (raw / "meta.txt").write_text("\n".join(lines) + "\n")
    model = root / "tiny.safetensors"
    _tiny_model(model)
    want = {}
    runs = (
        ("bag", ["--method", "classical"]),
        ("rig", ["--rig", str(rig), "--method", "classical"]),
        ("semattnet", ["--weights", str(model), "--device", "cpu"]),
    )
    for key, extra in runs:
        out = root / f"predict_{key}"
        res = CliRunner().invoke(
            main,
            [
                "predict",
                "--bag",
                str(bag),
                "--image-topic",
                TOPICS.image,
                "--points-topic",
                TOPICS.points,
                *extra,
                "--npy",
                "--out",
                str(out),
            ],
        )
        assert res.exit_code == 0, res.output
        want[key] = {T0 + i * STEP: np.load(out / f"{i:010d}.npy") for i in range(FRAMES)}  # the float depth
    return {"bag": bag, "rig": rig, "raw": raw, "want": want, "model": model}


def _tiny_model(path: Path) -> None:
    """A random width-0.125 SemAttNet (the method's code path, not its accuracy, is under test)."""
    import torch

    import semattnet
    from semattnet.weights import save_safetensors

    torch.manual_seed(0)
    save_safetensors(semattnet.build_model("semattnet", width=0.125).state_dict(), path)


def _node(*extra: str, model: tuple[str, ...] = ("--method", "classical")) -> dict[str, object]:
    """The node under test. ``--max-skew``: the frames repeat, so a lost scan must not widen the tolerance
    estimated from the few distinct stamps received (half the period) to the next frame."""
    argv = [
        sys.executable,
        "-m",
        "semattnet",
        "ros2",
        "--loopback",
        *model,
        "--image-topic",
        TOPICS.image,
        "--points-topic",
        TOPICS.points,
        "--camera-info-topic",
        TOPICS.camera_info,
        "--report-every",
        "1",
        "--max-skew",
        "0.02",
        *extra,
    ]
    return {"name": "node", "argv": argv}


def _check(out: Path, got_name: str, want: dict[int, np.ndarray], count: int, atol: float = 0.0) -> None:
    """Each received depth image: the input's stamp and camera frame id, pixels equal to predict --bag's
    (within ``atol`` metres)."""
    lines = (out / f"{got_name}.out").read_text().splitlines()
    assert len(lines) == count, (out / "node.err").read_text()[-3000:]
    for n, line in enumerate(lines):
        sec, nsec, frame_id, w, h, encoding, step = line.split()
        stamp = int(sec) * 10**9 + int(nsec)
        assert stamp in want and (frame_id, int(w), int(h), encoding, int(step)) == (
            TOPICS.camera_frame,
            W,
            H,
            "32FC1",
            4 * W,
        )
        pixels = np.fromfile(out / "rx" / f"{n}.bin", "<f4").reshape(H, W)
        np.testing.assert_allclose(pixels, np.where(want[stamp] > 0, want[stamp], np.nan), rtol=0, atol=atol)
    node_out = (out / "node.out").read_text()
    assert "ros node stopped:" in node_out and " 0 bad message(s)" in node_out, node_out


@pytest.mark.parametrize("method", ["classical", "semattnet"])
def test_cyclone_c_subscriber_receives_predict_bag_depth(
    peers: dict[str, Path], recorded: dict, tmp_path: Path, method: str
) -> None:
    """Our player (bag -> DDS, /tf_static transient local) drives the node; Cyclone 0.10 C receives its depth:
    classical bit for bit, the network within float rounding (bounded by one 1/256 m step)."""
    from semattnet.robotics.ros.dds import loopback_config

    model: tuple[str, ...] = ("--method", "classical")
    if method == "semattnet":
        model = ("--weights", str(recorded["model"]), "--device", "cpu")
    out = tmp_path / "run"
    (out / "rx").mkdir(parents=True)
    player = [
        sys.executable,
        str(HERE / "play.py"),
        str(recorded["bag"]),
        TOPICS.image,
        TOPICS.points,
        TOPICS.camera_info,
        "60",
    ]
    sub = [str(peers["cyclone"]), "rt" + OUT_TOPIC, "2", str(out / "rx"), "60"]
    env = {"CYCLONEDDS_URI": loopback_config(0)}
    status = run_isolated(
        out,
        [
            _node(model=model),
            {"name": "sub", "argv": sub, "env": env, "wait": True},
            {"name": "player", "argv": player, "delay": 1},
        ],
        70,
    )
    assert status["sub"] == 0 and status["node"] == 0, status
    want = recorded["want"]["bag" if method == "classical" else "semattnet"]
    _check(out, "sub", want, 2, atol=0.0 if method == "classical" else 1 / 256)


def test_fastdds_camera_drives_the_node_and_fastdds_receives(
    peers: dict[str, Path], recorded: dict, tmp_path: Path
) -> None:
    """Fast DDS (Humble's and Jazzy's default middleware) on both sides: a camera + LiDAR publisher, a subscriber."""
    out = tmp_path / "run"
    (out / "rx").mkdir(parents=True)
    pub = [str(peers["fastdds"]), "pub", "rt" + TOPICS.image, "rt" + TOPICS.points, str(recorded["raw"]), "60"]
    sub = [str(peers["fastdds"]), "sub", "rt" + OUT_TOPIC, "2", str(out / "rx"), "60"]
    status = run_isolated(
        out,
        [
            _node("--rig", str(recorded["rig"])),
            {"name": "sub", "argv": sub, "wait": True},
            {"name": "camera", "argv": pub, "delay": 1},
        ],
        70,
    )
    assert status["sub"] == 0 and status["node"] == 0, status
    _check(out, "sub", recorded["want"]["rig"], 2)
