"""Scenarios against Debian's ROS 1 (roscore, rostopic), run as a script so that a test can isolate it.

``python _ros1_peers.py echo|pub WORKDIR`` starts ``roscore`` on a free port (``ROS_HOME`` in WORKDIR),
runs the scenario with :class:`~semattnet.robotics.ros.tcpros.TcprosTransport` and prints one JSON line
of what the peers saw. Every wait is bounded; every process it starts is ended by its PID (roscore with
SIGINT, as its documentation asks). The test runs it inside a loopback-only network namespace.
"""

from __future__ import annotations

import functools
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from semattnet.robotics.bags.encode import depth_image_message
from semattnet.robotics.ros.tcpros import TcprosError, TcprosTransport
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS

STAMP = 1_700_000_000_123_456_789
H, W = 480, 640
DEADLINE_S = 45.0
IMAGE_YAML = (
    "{header: {stamp: {secs: 1700000001, nsecs: 5}, frame_id: camera_optical}, height: 2, width: 2,"
    " encoding: rgb8, is_bigendian: 0, step: 6, data: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]}"
)
INFO_YAML = (
    "{header: {stamp: {secs: 1700000002, nsecs: 7}, frame_id: camera_optical}, height: 2, width: 2,"
    " distortion_model: plumb_bob, K: [500.0, 0.0, 1.0, 0.0, 500.0, 1.0, 0.0, 0.0, 1.0]}"
)


def _stop(proc: subprocess.Popen[str], sig: int = signal.SIGINT) -> str:
    """End ``proc`` by its PID (``sig``, then SIGKILL after 10 s); its stdout."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate(timeout=5)
    return out or ""


@contextmanager
def _roscore(workdir: Path) -> Iterator[tuple[dict[str, str], TcprosTransport]]:
    """roscore on a free port, and our node on it once the master answers."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_IP="127.0.0.1", ROS_HOME=str(workdir))
    core = subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    transport = None
    try:
        deadline = time.monotonic() + DEADLINE_S
        while transport is None:
            try:
                transport = TcprosTransport(env["ROS_MASTER_URI"], "/semattnet", "127.0.0.1", timeout=3.0)
            except TcprosError:
                if time.monotonic() > deadline or core.poll() is not None:
                    raise
                time.sleep(0.2)
        yield env, transport
    finally:
        if transport is not None:
            transport.close()
        _stop(core)


def echo(workdir: Path) -> dict[str, Any]:
    """``rostopic echo --noarr -n 1`` of the 32FC1 depth image we publish."""
    with _roscore(workdir) as (env, transport):
        publisher = transport.advertise("/semattnet/depth_image", "sensor_msgs/msg/Image", OUTPUT_QOS)
        depth = np.full((H, W), 2.5, np.float32)
        message = depth_image_message(transport.typestore, depth, STAMP, "camera_optical")
        cmd = ["rostopic", "echo", "--noarr", "-n", "1", "/semattnet/depth_image"]
        peer = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        deadline = time.monotonic() + DEADLINE_S
        while peer.poll() is None and time.monotonic() < deadline:
            publisher.publish(message)
            time.sleep(0.1)
        return {"echo": _stop(peer), "returncode": peer.returncode}


PEER_MESSAGES = (("/camera/image_raw", "Image", IMAGE_YAML), ("/camera/camera_info", "CameraInfo", INFO_YAML))


def pub(workdir: Path) -> dict[str, Any]:
    """``rostopic pub`` of an Image and a CameraInfo, received by our subscribers."""
    received: dict[str, Any] = {}
    with _roscore(workdir) as (env, transport):
        for topic, msgtype, _ in PEER_MESSAGES:
            keep = functools.partial(received.setdefault, topic)
            transport.subscribe(topic, f"sensor_msgs/msg/{msgtype}", SENSOR_QOS, keep)
        peers = [
            subprocess.Popen(["rostopic", "pub", "-r", "5", topic, f"sensor_msgs/{msgtype}", text], env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
            for topic, msgtype, text in PEER_MESSAGES
        ]  # fmt: skip
        deadline = time.monotonic() + DEADLINE_S
        while len(received) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        for peer in peers:
            _stop(peer)
    image, info = received.get("/camera/image_raw"), received.get("/camera/camera_info")
    return {
        "image": None if image is None else {
            "stamp": [image.header.stamp.sec, image.header.stamp.nanosec], "frame_id": image.header.frame_id,
            "size": [image.height, image.width], "encoding": image.encoding, "data": image.data.tolist()},
        "info": None if info is None else {
            "stamp": [info.header.stamp.sec, info.header.stamp.nanosec], "frame_id": info.header.frame_id,
            "K": info.K.tolist(), "distortion_model": info.distortion_model},
    }  # fmt: skip


if __name__ == "__main__":
    scenario = {"echo": echo, "pub": pub}[sys.argv[1]]
    print(json.dumps(scenario(Path(sys.argv[2]))))
