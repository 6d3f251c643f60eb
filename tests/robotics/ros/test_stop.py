"""A bounded stop: ``semattnet ros2`` ends within about a second of SIGINT / SIGTERM whatever the model, exit
status 0, abandoning the frame in hand and saying so; measured against the frame's own duration, not a clock."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("cyclonedds")
pytest.importorskip("rosbags")

from semattnet.robotics.ros.dds import DdsTransport
from semattnet.robotics.ros.transport import SENSOR_QOS, TF_STATIC_QOS

from ._fakes import camera_info, image, scan, tf_static

#: The slow completer's extra seconds per frame (a slow model on a busy CPU).
FRAME_S = 4.0
DOMAIN = 47

CHILD = textwrap.dedent(
    """
    import sys, time
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.cli import _model

    log = open(sys.argv[1], "a", buffering=1)

    class Slow(ClassicalCompleter):
        def __call__(self, rgb, sparse, semantic=None):
            log.write(f"start {time.monotonic()}\\n")
            time.sleep(float(sys.argv[2]))
            out = super().__call__(rgb, sparse, semantic)
            log.write(f"end {time.monotonic()}\\n")
            return out

    _model.ModelOptions.completer = lambda self: Slow()
    from semattnet.cli import main

    main(["ros2", "--loopback", "--domain-id", sys.argv[3], "--method", "classical", "--report-every", "60"])
    """
)


def _events(path: Path) -> list[tuple[str, float]]:
    if not path.exists():
        return []
    return [(k, float(v)) for k, v in (line.split() for line in path.read_text().splitlines() if line.strip())]


def _feed(stop: threading.Event) -> None:
    """The camera, its CameraInfo, the LiDAR and /tf_static at 10 Hz (the test's sensors) until ``stop``."""
    t = DdsTransport(DOMAIN, loopback=True)
    try:
        pubs = {
            "image": t.advertise("/semattnet/input/image", "sensor_msgs/msg/Image", SENSOR_QOS),
            "scan": t.advertise("/semattnet/input/point_cloud", "sensor_msgs/msg/PointCloud2", SENSOR_QOS),
            "info": t.advertise("/semattnet/input/camera_info", "sensor_msgs/msg/CameraInfo", SENSOR_QOS),
        }
        t.advertise("/tf_static", "tf2_msgs/msg/TFMessage", TF_STATIC_QOS).publish(tf_static())
        k = 0
        while not stop.wait(0.1):
            stamp = 1_700_000_000_000_000_000 + k * 100_000_000
            pubs["info"].publish(camera_info(stamp))
            pubs["scan"].publish(scan(stamp))
            pubs["image"].publish(image(stamp))
            k += 1
    finally:
        t.close()


@pytest.mark.parametrize("signame", ["SIGINT", pytest.param("SIGTERM", marks=pytest.mark.slow)])
def test_a_signal_mid_frame_ends_the_node_long_before_the_frame_would(tmp_path: Path, signame: str) -> None:
    events = tmp_path / "events.txt"
    repo = Path(__file__).resolve().parents[3]
    env = {**os.environ, "PYTHONPATH": str(repo / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")}
    node = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(events), str(FRAME_S), str(DOMAIN)],
        cwd=repo,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    stop = threading.Event()
    feeder = threading.Thread(target=_feed, args=(stop,), daemon=True)
    feeder.start()
    try:
        deadline = time.monotonic() + 90  # a hang guard, not a budget
        while sum(k == "start" for k, _ in _events(events)) < 2 and time.monotonic() < deadline:
            if node.poll() is not None:
                break
            time.sleep(0.05)
        got = _events(events)
        assert [k for k, _ in got[:3]] == ["start", "end", "start"], (got, node.poll())
        frame_s = got[1][1] - got[0][1]  # one whole frame, measured
        time.sleep(0.3)
        sent = time.monotonic()
        node.send_signal(getattr(signal, signame))
        out, _ = node.communicate(timeout=max(10.0, 3 * frame_s))
        took = time.monotonic() - sent
    finally:
        stop.set()
        if node.poll() is None:
            node.kill()
        feeder.join(10)
    assert node.returncode == 0, out[-3000:]
    assert took < 0.6 * frame_s, (took, frame_s, out[-3000:])  # the frame in hand had >= 3.7 s left
    assert "stopped mid-frame: frame 17000000" in out and "abandoned" in out, out[-3000:]
    assert "ros node stopped: 1 frame(s) published" in out, out[-3000:]
    assert sum(k == "end" for k, _ in _events(events)) == 1  # the second frame never finished
