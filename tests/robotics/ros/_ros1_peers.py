"""Scenarios against Debian's ROS 1 (roscore, rostopic), run as a script so that a test can isolate it.

``python _ros1_peers.py echo|pub|node WORKDIR`` starts ``roscore`` on a free port (``ROS_HOME`` in WORKDIR),
runs the scenario with :class:`~semattnet.robotics.ros.tcpros.TcprosTransport` (``node``: the
``semattnet ros1`` command, fed from the bag ``WORKDIR/drive_mcap``) and prints one JSON line of what the
peers saw. Every wait is bounded; every process it starts is ended by its PID (roscore with
SIGINT, as its documentation asks). The test runs it inside a loopback-only network namespace.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from semattnet.robotics.bags import BagTopics, open_bag
from semattnet.robotics.bags.decode import msg_stamp_ns
from semattnet.robotics.bags.encode import depth_image_message
from semattnet.robotics.ros.tcpros import TcprosError, TcprosPublisher, TcprosTransport
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS, TF_STATIC_QOS

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
def _roscore(workdir: Path, name: str = "/semattnet") -> Iterator[tuple[dict[str, str], TcprosTransport]]:
    """roscore on a free port, and our node ``name`` on it once the master answers."""
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
                transport = TcprosTransport(env["ROS_MASTER_URI"], name, "127.0.0.1", timeout=3.0)
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


def bus(workdir: Path) -> dict[str, Any]:
    """``rosnode info`` of our node while ``rostopic echo`` subscribes its depth and ``rostopic pub`` feeds its
    image subscriber: the connections getBusInfo lists."""
    with _roscore(workdir) as (env, transport):
        publisher = transport.advertise("/semattnet/depth_image", "sensor_msgs/msg/Image", OUTPUT_QOS)
        transport.subscribe("/camera/image_raw", "sensor_msgs/msg/Image", SENSOR_QOS, lambda message: None)
        message = depth_image_message(transport.typestore, np.full((4, 4), 2.5, np.float32), STAMP, "camera")
        commands = (
            ["rostopic", "echo", "--noarr", "/semattnet/depth_image"],
            ["rostopic", "pub", "-r", "5", "/camera/image_raw", "sensor_msgs/Image", IMAGE_YAML],
        )
        peers = [
            subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
            for cmd in commands
        ]
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline and {row[2] for row in transport.bus_info()} != {"i", "o"}:
            publisher.publish(message)
            time.sleep(0.1)
        info = subprocess.run(["rosnode", "info", "/semattnet"], env=env, capture_output=True, text=True, timeout=30)
        for peer in peers:
            _stop(peer)
    return {"info": info.stdout + info.stderr}


PEER_MESSAGES = (("/camera/image_raw", "Image", IMAGE_YAML), ("/camera/camera_info", "CameraInfo", INFO_YAML))


def pub(workdir: Path) -> dict[str, Any]:
    """``rostopic pub`` of an Image and a CameraInfo, received by our subscribers."""
    received: dict[str, Any] = {}
    with _roscore(workdir) as (env, transport):
        for topic, msgtype, _ in PEER_MESSAGES:
            keep = functools.partial(received.setdefault, topic)
            transport.subscribe(topic, f"sensor_msgs/msg/{msgtype}", SENSOR_QOS, keep)
        peers = [
            subprocess.Popen(
                ["rostopic", "pub", "-r", "5", topic, f"sensor_msgs/{msgtype}", text],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            for topic, msgtype, text in PEER_MESSAGES
        ]
        deadline = time.monotonic() + DEADLINE_S
        while len(received) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        for peer in peers:
            _stop(peer)
    image, info = received.get("/camera/image_raw"), received.get("/camera/camera_info")
    return {
        "image": None
        if image is None
        else {
            "stamp": [image.header.stamp.sec, image.header.stamp.nanosec],
            "frame_id": image.header.frame_id,
            "size": [image.height, image.width],
            "encoding": image.encoding,
            "data": image.data.tolist(),
        },
        "info": None
        if info is None
        else {
            "stamp": [info.header.stamp.sec, info.header.stamp.nanosec],
            "frame_id": info.header.frame_id,
            "K": info.K.tolist(),
            "distortion_model": info.distortion_model,
        },
    }


#: How many frames ``semattnet ros1 --frames`` completes before it stops on its own.
NODE_FRAMES = 5
NODE_DEPTH = "/semattnet/output/depth_image"


def _camera_info_yaml(info: Any) -> str:
    """A bag's (ROS 2) CameraInfo as ``rostopic pub``'s YAML (JSON is YAML), in ROS 1's field names."""
    stamp = {"secs": int(info.header.stamp.sec), "nsecs": int(info.header.stamp.nanosec)}
    return json.dumps(
        {
            "header": {"stamp": stamp, "frame_id": info.header.frame_id},
            "height": int(info.height),
            "width": int(info.width),
            "distortion_model": info.distortion_model,
            "D": info.d.tolist(),
            "K": info.k.tolist(),
            "R": info.r.tolist(),
            "P": info.p.tolist(),
        }
    )


def _subscribed(env: dict[str, str], topic: str) -> bool:
    """Whether the master lists a subscriber of ``topic``."""
    code, _, (_, subscribers, _) = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"]).getSystemState("/probe")
    return code == 1 and any(name == topic and nodes for name, nodes in subscribers)


def _drive(
    env: dict[str, str],
    static: TcprosPublisher,
    frames: list[tuple[TcprosPublisher, Any]],
    procs: dict[str, subprocess.Popen[str]],
) -> None:
    """Once the node has subscribed (/tf_static, its last input) and ``rostopic echo`` waits for its depth,
    publish the bag's images and clouds at 10 Hz, round and round, until the node has stopped (bounded)."""
    deadline = time.monotonic() + DEADLINE_S
    while static.subscriber_count < 1 or not _subscribed(env, NODE_DEPTH):
        if time.monotonic() > deadline or procs["node"].poll() is not None:
            return
        time.sleep(0.1)
    time.sleep(1.0)  # the node's connection to rostopic pub's latched CameraInfo is made meanwhile
    while procs["node"].poll() is None and time.monotonic() < deadline:
        for publisher, message in frames:
            publisher.publish(message)
            time.sleep(0.05)


def node(workdir: Path) -> dict[str, Any]:
    """``semattnet ros1 --frames`` with its CameraInfo from ``rostopic pub -l`` and its image, cloud and latched
    /tf_static from our camera driver (the bag): what ``rostopic echo -n 1`` printed of the node's depth, and
    the node's exit status and output."""
    topics = BagTopics()
    with open_bag(workdir / "drive_mcap") as reader:
        msgs = {
            c.topic: [reader.deserialize(raw, c.msgtype) for _, _, raw in reader.messages([c])]
            for c in reader.connections
        }
    with _roscore(workdir, "/camera_driver") as (env, transport):
        static = transport.advertise(topics.tf_static, "tf2_msgs/msg/TFMessage", TF_STATIC_QOS)
        static.publish(msgs[topics.tf_static][0])
        image = transport.advertise(topics.image, "sensor_msgs/msg/Image", SENSOR_QOS)
        cloud = transport.advertise(topics.points, "sensor_msgs/msg/PointCloud2", SENSOR_QOS)
        frames = [(image, m) for m in msgs[topics.image]] + [(cloud, m) for m in msgs[topics.points]]
        frames.sort(key=lambda frame: msg_stamp_ns(frame[1].header.stamp))
        info = _camera_info_yaml(msgs[topics.camera_info][0])
        argv = {
            "info": ["rostopic", "pub", "-l", topics.camera_info, "sensor_msgs/CameraInfo", info],
            "echo": ["rostopic", "echo", "-n", "1", NODE_DEPTH],
            "rosout": ["rostopic", "echo", "/rosout_agg"],  # what roscore's rosout node received of /rosout
            "node": [
                sys.executable,
                "-m",
                "semattnet",
                "ros1",
                "--master",
                env["ROS_MASTER_URI"],
                "--method",
                "classical",
                "--frames",
                str(NODE_FRAMES),
                "--image-topic",
                topics.image,
                "--points-topic",
                topics.points,
                "--camera-info-topic",
                topics.camera_info,
                "--max-skew",
                "0.02",
                "--report-every",
                "0.2",
            ],
        }
        procs = {}
        for name, cmd in argv.items():
            with (workdir / f"{name}.out").open("w") as out:
                procs[name] = subprocess.Popen(
                    cmd, env=os.environ if name == "node" else env, text=True, stdout=out, stderr=subprocess.STDOUT
                )
        _drive(env, static, frames, procs)
        for name in ("node", "echo", "rosout", "info"):  # the node and echo end on their own; the others by their PID
            if name in ("node", "echo"):
                with contextlib.suppress(subprocess.TimeoutExpired):
                    procs[name].wait(10)
            _stop(procs[name])
    read = {name: (workdir / f"{name}.out").read_text() for name in procs}
    return {
        "echo": read["echo"],
        "rosout": read["rosout"],
        "node": read["node"],
        "node_returncode": procs["node"].returncode,
    }


if __name__ == "__main__":
    scenario = {"echo": echo, "pub": pub, "node": node, "bus": bus}[sys.argv[1]]
    print(json.dumps(scenario(Path(sys.argv[2]))))
