"""The ROS 1 transport and ``semattnet ros1`` against Debian's ROS 1 (``roscore``, ``rostopic``): a foreign master
and foreign nodes.

Each scenario (:mod:`._ros1_peers`) runs in its own loopback-only network namespace where ``unshare
--net`` works (root), else on 127.0.0.1. Install the tools with ``scripts/setup-ros1-peers.sh``; run
with ``pytest -m ros_peers`` (they skip without the tools, and fail instead with ``SEMATTNET_REQUIRE_ROS1=1``).
"""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

import semattnet
from semattnet.cli import main
from semattnet.geometry import RigCalibration

from ..peers.test_peers import STEP, T0, T_CAM_LIDAR, TOPICS, H, K, W, _record

pytest.importorskip("rosbags")
from semattnet.robotics.bags import write_sensor_bag

pytestmark = pytest.mark.ros_peers

SCENARIOS = Path(__file__).with_name("_ros1_peers.py")


@pytest.fixture(autouse=True)
def _ros1_tools() -> None:
    """Skip without Debian's ROS 1 tools; fail instead in CI (``SEMATTNET_REQUIRE_ROS1=1``)."""
    missing = [name for name in ("roscore", "rostopic") if not shutil.which(name)]
    if missing:
        why = f"Debian's ROS 1 tools are missing ({', '.join(missing)}): run scripts/setup-ros1-peers.sh"
        if os.environ.get("SEMATTNET_REQUIRE_ROS1"):
            pytest.fail(why)
        pytest.skip(why)


@functools.lru_cache(maxsize=1)
def _isolation() -> tuple[str, ...]:
    """The command prefix that runs a command in a fresh loopback-only network namespace; () where it cannot."""
    prefix = ("unshare", "--net", "sh", "-c", 'ip link set lo up && exec "$@"', "sh")
    if not (shutil.which("unshare") and shutil.which("ip")):
        return ()
    probe = subprocess.run([*prefix, "true"], capture_output=True, timeout=10)
    return prefix if probe.returncode == 0 else ()


def _scenario(name: str, workdir: Path) -> dict[str, Any]:
    env = dict(os.environ, PYTHONPATH=str(Path(semattnet.__file__).parents[1]))
    cmd = [*_isolation(), sys.executable, str(SCENARIOS), name, str(workdir)]
    # Its own process group: if it ever outlives its bounded waits, it goes with its roscore and rostopic.
    proc = subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err[-4000:]
    return json.loads(out.splitlines()[-1])


def test_rostopic_echo_receives_our_depth(tmp_path: Path) -> None:
    """A 480x640 32FC1 image we publish reaches ``rostopic echo`` with its stamp, frame id, encoding and size."""
    result = _scenario("echo", tmp_path)
    text = result["echo"]
    assert result["returncode"] == 0, text
    fields = dict(re.findall(r"^\s*(\w+): (.*)$", text, re.MULTILINE))
    assert (fields["secs"], fields["nsecs"]) == ("1700000000", "123456789")
    assert fields["frame_id"] == '"camera_optical"'
    assert fields["encoding"] == '"32FC1"'
    assert (fields["height"], fields["width"], fields["step"]) == ("480", "640", str(4 * 640))
    assert fields["data"] == f'"<array type: uint8, length: {480 * 640 * 4}>"'


def test_rostopic_pub_reaches_our_subscriber(tmp_path: Path) -> None:
    """An Image and a CameraInfo from ``rostopic pub`` arrive in our subscribers' callbacks, fields intact."""
    result = _scenario("pub", tmp_path)
    assert result["image"] == {
        "stamp": [1700000001, 5],
        "frame_id": "camera_optical",
        "size": [2, 2],
        "encoding": "rgb8",
        "data": list(range(1, 13)),
    }
    assert result["info"] == {
        "stamp": [1700000002, 7],
        "frame_id": "camera_optical",
        "distortion_model": "plumb_bob",
        "K": [500.0, 0.0, 1.0, 0.0, 500.0, 1.0, 0.0, 0.0, 1.0],
    }


def test_rosnode_info_lists_our_connections(tmp_path: Path) -> None:
    """Debian's ``rosnode info`` shows the node's connections from its getBusInfo: the depth topic outbound to
    ``rostopic echo``, the image topic inbound from ``rostopic pub``, each over TCPROS with rospy's description."""
    text = _scenario("bus", tmp_path)["info"]
    assert "Connections:" in text, text
    outbound = re.search(r"\* topic: /semattnet/depth_image\n +\* to: /rostopic_\w+\n +\* direction: outbound \(", text)
    inbound = re.search(
        r"\* topic: /camera/image_raw\n +\* to: /rostopic_\w+ \(http://[\d.:]+/\)\n +\* direction: inbound \(", text
    )
    assert outbound and inbound and text.count("* transport: TCPROS") == 2, text


@pytest.fixture
def drive(tmp_path: Path) -> dict[int, np.ndarray]:
    """A 3-frame camera + LiDAR bag (``tmp_path/drive_mcap``, what the node's inputs play) and ``predict --bag``'s
    float depth of it (classical, ``--npy``: what the node publishes, not the PNG's 1/256 m steps), by image
    stamp."""
    rng = np.random.default_rng(5)
    records = [_record(i, rng) for i in range(3)]
    bag = write_sensor_bag(tmp_path / "drive_mcap", records, RigCalibration(K, T_CAM_LIDAR, (W, H))).path
    out = tmp_path / "predict"
    argv = [
        "predict",
        "--bag",
        str(bag),
        "--image-topic",
        TOPICS.image,
        "--points-topic",
        TOPICS.points,
        "--method",
        "classical",
        "--npy",
        "--out",
        str(out),
    ]
    result = CliRunner().invoke(main, argv)
    assert result.exit_code == 0, result.output
    return {T0 + i * STEP: np.load(out / f"{i:010d}.npy") for i in range(3)}  # the float depth the node publishes


def test_ros1_node_driven_by_rostopic_pub_reaches_rostopic_echo(tmp_path: Path, drive: dict[int, np.ndarray]) -> None:
    """``semattnet ros1 --frames 5`` on a Debian roscore, its CameraInfo from ``rostopic pub -l`` (latched) and its
    image, cloud and /tf_static from our driver: ``rostopic echo`` receives its 32FC1 depth with the image's stamp
    and frame id, pixels equal to ``predict --bag``'s (classical: exact), and the node stops on its own."""
    result = _scenario("node", tmp_path)
    log = result["node"]
    assert result["node_returncode"] == 0, log
    assert "ros node stopped: 5 frame(s) published" in log and " 0 bad message(s)" in log, log
    fields = dict(re.findall(r"^\s*(\w+): (.*)$", result["echo"], re.MULTILINE))
    assert "data" in fields, result["echo"][-2000:]
    stamp = int(fields["secs"]) * 1_000_000_000 + int(fields["nsecs"])
    assert stamp in drive and fields["frame_id"] == f'"{TOPICS.camera_frame}"' and int(fields["seq"]) >= 1
    assert (fields["encoding"], fields["is_bigendian"]) == ('"32FC1"', "0")
    assert (fields["height"], fields["width"], fields["step"]) == (str(H), str(W), str(4 * W))
    pixels = np.frombuffer(bytes(json.loads(fields["data"])), "<f4").reshape(H, W)
    want = drive[stamp]
    assert np.count_nonzero(want) and np.ptp(want) > 1.0  # a wall and a box: not a constant image
    np.testing.assert_array_equal(pixels, np.where(want > 0, want, np.float32(np.nan)))
    # its report lines went over /rosout to roscore's rosout node, which republished them on /rosout_agg
    ours = [block for block in result["rosout"].split("---") if 'name: "/semattnet"' in block]
    assert ours and any("level: 2" in block and "frame(s)" in block for block in ours), result["rosout"][-2000:]
