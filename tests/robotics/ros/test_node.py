"""The live node over an in-process transport: newest pair only, drops counted, bad messages skipped."""

from __future__ import annotations

import logging
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from semattnet.inference.contract import Completion
from semattnet.robotics.ros.node import DepthNode, NodeTopics
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS, TF_QOS, TF_STATIC_QOS

from ._fakes import INFO, TS, FakeTransport, camera_info, image, scan, tf_static

pytest.importorskip("rosbags")

NS = "/robot1"
IMAGE, SCAN, INFO_T = "/robot1/semattnet/input/image", "/robot1/semattnet/input/point_cloud", "/robot1/cam/info"
OUT = "/robot1/semattnet/output"
T0 = 1_700_000_000_000_000_000
STEP = 100_000_000


def _complete(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
    """Depth = the stamp-free constant 7.5 m with one hole; the sparse input must have points."""
    assert (sparse > 0).any()
    depth = np.full(sparse.shape, 7.5, np.float32)
    depth[0, 0] = 0
    return Completion(depth)


def _node(lines: list[str] | None = None) -> tuple[DepthNode, FakeTransport]:
    fake = FakeTransport()
    topics = NodeTopics(camera_info="cam/info")  # remapped (relative: in the namespace)
    node = DepthNode(fake, _complete, topics, namespace=NS, say=(lines if lines is not None else []).append)
    node.start()
    fake.deliver(INFO_T, camera_info())
    fake.deliver("/tf_static", tf_static())
    return node, fake


def _spin(node: DepthNode, frames: int = 1) -> None:
    stop = threading.Event()
    threading.Timer(5.0, stop.set).start()  # bounded, whatever happens
    node.spin(stop, frames=frames)
    stop.set()


def test_topics_qos_and_one_frame() -> None:
    node, fake = _node()
    assert {t: (m, q) for t, (m, q, _) in fake.subs.items()} == {
        IMAGE: ("sensor_msgs/msg/Image", SENSOR_QOS),
        SCAN: ("sensor_msgs/msg/PointCloud2", SENSOR_QOS),
        INFO_T: ("sensor_msgs/msg/CameraInfo", SENSOR_QOS),
        "/tf_static": ("tf2_msgs/msg/TFMessage", TF_STATIC_QOS),
        "/tf": ("tf2_msgs/msg/TFMessage", TF_QOS),
    }
    assert TF_QOS.reliable and not TF_QOS.durable and TF_QOS.depth == 100
    assert OUTPUT_QOS.reliable and OUTPUT_QOS.depth == 1
    fake.deliver(IMAGE, image(T0))
    fake.deliver(SCAN, scan(T0 + 5_000_000))
    _spin(node)
    out = {t.removeprefix(OUT + "/"): m for t, m in fake.published.items() if t.startswith(OUT)}
    assert sorted(out) == ["camera_info", "depth_image", "point_cloud"]  # a completer that gives no uncertainty
    depth = out["depth_image"][0]
    assert (depth.header.stamp.sec, depth.header.stamp.nanosec, depth.header.frame_id) == (T0 // 10**9, 0, "cam")
    pixels = np.frombuffer(depth.data.tobytes(), "<f4").reshape(INFO.height, INFO.width)
    assert np.isnan(pixels[0, 0]) and (pixels.ravel()[1:] == 7.5).all()
    assert out["camera_info"][0].header == depth.header == out["point_cloud"][0].header
    assert out["point_cloud"][0].width == 3 * 4 - 1  # every 4th pixel both ways (the default stride), one hole


def test_messages_are_built_in_the_transports_type_store() -> None:
    """Over TCPROS (its ``typestore``: ROS 1 Noetic's) the outputs are ROS 1 messages (``CameraInfo.K``), built
    once per frame, not ROS 2 ones converted on every publish."""
    from semattnet.robotics.bags.deps import rosbags_typestore

    fake = FakeTransport()
    fake.typestore = ros1 = rosbags_typestore(True)
    node = DepthNode(fake, _complete, NodeTopics(camera_info="cam/info"), namespace=NS).start()
    for topic, message in (
        (INFO_T, camera_info()),
        ("/tf_static", tf_static()),
        (IMAGE, image(T0)),
        (SCAN, scan(T0 + 5_000_000)),
    ):
        fake.deliver(topic, message)
    _spin(node)
    info = fake.published[OUT + "/camera_info"][0]
    assert type(info) is ros1.types["sensor_msgs/msg/CameraInfo"]
    np.testing.assert_array_equal(info.K.reshape(3, 3), INFO.K)
    assert type(fake.published[OUT + "/depth_image"][0]) is ros1.types["sensor_msgs/msg/Image"]


def test_newest_pair_only_stale_pairs_counted() -> None:
    """Pairs made while the worker is busy replace each other in one slot: only the newest is completed."""
    lines: list[str] = []
    node, fake = _node(lines)
    for i in range(4):
        fake.deliver(IMAGE, image(T0 + i * STEP))
        fake.deliver(SCAN, scan(T0 + i * STEP))
    _spin(node)
    (depth,) = fake.published[f"{OUT}/depth_image"]
    assert depth.header.stamp.nanosec == 3 * STEP  # the newest
    c, status = node.inputs.counts, node.status()
    assert (c.paired, status.stale, c.unpaired, c.bad, node.published) == (4, 3, 0, 0, 1)
    assert status.accounted and status.in_flight == 0 and status.topics["image"].decoded == 1  # the one completed
    assert "1 frame(s) published, 3 stale pair(s) dropped" in lines[-1] and "network" in lines[-1]


def test_image_waits_for_its_scan_and_unpaired_are_counted() -> None:
    node, fake = _node()
    fake.deliver(IMAGE, image(T0))
    fake.deliver(SCAN, scan(T0 - STEP))  # before the image: not decided yet (a nearer one may come)
    assert node.inputs.counts.paired == 0
    fake.deliver(SCAN, scan(T0 + STEP // 10))
    assert node.inputs.counts.paired == 1  # the nearer one
    fake.deliver(IMAGE, image(T0 + 5 * STEP))  # no scan near it ...
    fake.deliver(IMAGE, image(T0 + 6 * STEP))  # ... decided when a newer image comes
    assert node.inputs.counts.unpaired == 1


def _bad_cases() -> list[tuple[str, object, str]]:
    trunc = image(T0)
    trunc = replace(trunc, data=trunc.data[:10])  # type: ignore[type-var]
    odd = replace(image(T0), encoding="nv21")  # type: ignore[type-var]
    nan_info = camera_info()
    nan_info.k[0] = np.nan  # type: ignore[attr-defined]
    no_xyz = TS.types["sensor_msgs/msg/PointCloud2"](
        header=scan(T0).header,
        height=1,
        width=0,
        fields=[],  # type: ignore[attr-defined]
        is_bigendian=False,
        point_step=0,
        row_step=0,
        data=np.zeros(0, np.uint8),
        is_dense=True,
    )
    return [
        (IMAGE, trunc, "holds 10 bytes"),
        (IMAGE, odd, "unsupported image encoding 'nv21'"),
        (INFO_T, nan_info, "is NaN"),
        (SCAN, no_xyz, "no x/y/z field"),
    ]


def test_bad_messages_are_one_line_each_and_the_node_goes_on(caplog: pytest.LogCaptureFixture) -> None:
    """A CameraInfo that does not decode is one line when it comes; an image or a scan is decoded only when its
    pair is completed, so a bad one fails its frame (one line naming its topic and message) and the node goes on."""
    node, fake = _node()
    done = 0
    with caplog.at_level(logging.WARNING, logger="semattnet.ros"):
        for i, (topic, msg, why) in enumerate(_bad_cases()):
            caplog.clear()
            stamp = T0 + i * STEP
            if topic == INFO_T:
                fake.deliver(topic, msg)
            else:
                good = {IMAGE: image(stamp), SCAN: scan(stamp)}
                good[topic] = replace(msg, header=replace(msg.header, stamp=good[topic].header.stamp))  # type: ignore[type-var, attr-defined]
                fake.deliver(IMAGE, good[IMAGE])
                fake.deliver(SCAN, good[SCAN])
                done += 1
                _spin(node, frames=done)
            (rec,) = caplog.records
            assert rec.getMessage().startswith(f"{topic} message ") and why in rec.getMessage(), rec.getMessage()
            assert "\n" not in rec.getMessage()
        behind = np.array([[-5.0, 0, 0], [-6.0, 1, 0]], np.float32)  # every point behind the camera
        caplog.clear()
        fake.deliver(IMAGE, image(T0 + 10 * STEP))
        fake.deliver(SCAN, scan(T0 + 10 * STEP, behind))
        _spin(node, frames=done + 1)  # the frame fails
    assert node.failed == 4 and "no point in front of the camera" in caplog.text
    fake.deliver(SCAN, scan(T0 + 11 * STEP))  # first: the image is paired when it comes
    fake.deliver(IMAGE, image(T0 + 11 * STEP))
    _spin(node, frames=done + 2)  # one failed, one published
    assert node.published == 1 and node.failed == 4 and node.inputs.counts.bad == 4


def test_sigterm_stops_cleanly_and_prints_the_summary() -> None:
    """run_node: SIGTERM only sets the stop event; the summary is said, the transport closed, handlers restored.

    In a fresh process: a SIGTERM raised inside the suite's process, beside the worker threads earlier tests left
    (OpenVINO's, torch's), crashed it (SIGSEGV) in two full runs of the suite."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(
        """
        import os, signal, threading
        from semattnet.robotics.ros.node import run_node
        from tests.robotics.ros.test_node import DepthNode, FakeTransport, _complete
        lines = []
        fake = FakeTransport()
        node = DepthNode(fake, _complete, say=lines.append)
        before = signal.getsignal(signal.SIGTERM)
        threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGTERM)).start()
        run_node(node)
        assert fake.closed and lines[-1].startswith("ros node stopped: 0 frame(s) published"), lines
        assert signal.getsignal(signal.SIGTERM) is before
        print("stopped cleanly")
        """
    )
    repo = Path(__file__).resolve().parents[3]
    r = subprocess.run([sys.executable, "-c", code], cwd=repo, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip().endswith("stopped cleanly"), r.stderr[-2000:]


# SIGTERM is slow (a fresh interpreter, ~5 s): by default [SIGINT] tests the loop closing the viewer and
# test_sigterm_stops_cleanly_and_prints_the_summary the node's SIGTERM handling.
@pytest.mark.parametrize("signame", ["SIGINT", pytest.param("SIGTERM", marks=pytest.mark.slow)])
def test_a_signal_closes_the_live_viewer_beside_the_node(signame: str) -> None:
    """``--live`` beside the node is a sink of the loop: SIGINT or SIGTERM stops the node and the loop closes the
    viewer, so its port is free again (in a fresh process, as above)."""
    import subprocess
    import sys
    import textwrap

    pytest.importorskip("foxglove")
    code = textwrap.dedent(
        f"""
        import os, signal, socket, threading
        from semattnet.robotics.live import LiveSink
        from semattnet.robotics.ros.node import run_node
        from tests.robotics.ros.test_node import DepthNode, FakeTransport, _complete
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        viewer = LiveSink(address=f"127.0.0.1:{{port}}", log=lambda _: None)
        node = DepthNode(FakeTransport(), _complete, say=[].append, sinks=[viewer])

        def kill():
            with socket.create_connection(("127.0.0.1", port), timeout=5):  # the viewer serves while the node runs
                pass
            os.kill(os.getpid(), signal.{signame})

        threading.Timer(1.0, kill).start()
        run_node(node)
        with socket.socket() as s:
            s.bind(("127.0.0.1", port))  # free again: the loop closed the viewer
        print("port free")
        """
    )
    repo = Path(__file__).resolve().parents[3]
    r = subprocess.run([sys.executable, "-c", code], cwd=repo, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip().endswith("port free"), r.stderr[-2000:]


def test_viewers_run_beside_the_node() -> None:
    """Run outputs (``--live``, ``--rerun-serve``) get every published frame, opened and finished with the node."""
    from semattnet.inference.sinks import RunSink

    class Recorder(RunSink):
        def __init__(self) -> None:
            self.events: list[str] = []

        def open(self, overwrite: bool = False) -> None:
            self.events.append("open")

        def write(self, stage: object, pred: object) -> None:
            self.events.append(f"write {pred.frame.meta.stamp_ns}")  # type: ignore[attr-defined]

        def finish(self, stage: object) -> None:
            self.events.append("finish")

    viewer = Recorder()
    fake = FakeTransport()
    node = DepthNode(
        fake, _complete, NodeTopics(camera_info="cam/info"), namespace=NS, say=[].append, sinks=[viewer]
    ).start()
    fake.deliver(INFO_T, camera_info())
    fake.deliver("/tf_static", tf_static())
    fake.deliver(IMAGE, image(T0))
    fake.deliver(SCAN, scan(T0))
    _spin(node)
    node.close()
    assert viewer.events == ["open", f"write {T0}", "finish"] and fake.closed


def test_compressed_image_and_sparse_depth_inputs() -> None:
    """CompressedImage in; a sparse depth Image (32FC1 m, NaN = none) instead of a cloud: used as it is."""
    from semattnet.robotics.bags.encode import compressed_image_message, depth_image_message

    seen: list[np.ndarray] = []

    def complete(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        seen.append(sparse)
        return _complete(rgb, sparse, semantic)

    fake = FakeTransport()
    node = DepthNode(
        fake, complete, NodeTopics(image="camera/image/compressed"), compressed=True, sparse=True, say=[].append
    ).start()
    assert fake.subs["/camera/image/compressed"][0] == "sensor_msgs/msg/CompressedImage"
    assert fake.subs["/semattnet/input/point_cloud"][0] == "sensor_msgs/msg/Image" and "/tf_static" not in fake.subs
    sparse = np.zeros((INFO.height, INFO.width), np.float32)
    sparse[3, 4], sparse[7, 9] = 5.5, 12.25
    fake.deliver("/semattnet/input/camera_info", camera_info())
    fake.deliver("/camera/image/compressed", compressed_image_message(TS, np.zeros((12, 16, 3), np.uint8), T0, "cam"))
    fake.deliver("/semattnet/input/point_cloud", depth_image_message(TS, sparse, T0, "cam"))
    _spin(node)
    assert node.published == 1 and len(seen) == 1
    np.testing.assert_array_equal(seen[0], sparse)


def test_sparse_depth_16uc1_is_millimetres() -> None:
    from semattnet.robotics.ros.inputs import decode_sparse_depth

    mm = np.array([[0, 1500], [65535, 250]], "<u2")
    data = np.frombuffer(mm.tobytes(), np.uint8)
    msg = TS.types["sensor_msgs/msg/Image"](
        header=image(T0).header,
        height=2,
        width=2,
        encoding="16UC1",  # type: ignore[attr-defined]
        is_bigendian=0,
        step=4,
        data=data,
    )
    np.testing.assert_allclose(decode_sparse_depth(msg, "/d"), [[0, 1.5], [65.535, 0.25]], rtol=1e-6)


@pytest.mark.parametrize(
    ("step", "why"), [(160, "rows of 40 pixels take 80 bytes, the message's rows 160"), (80, "make 160")]
)
def test_sparse_depth_whose_data_is_not_its_encoding_is_refused(step: int, why: str) -> None:
    """32FC1 data (4 bytes a pixel) sent as 16UC1: by its step, or by its size against a 16UC1 step."""
    from semattnet._errors import DataError
    from semattnet.robotics.ros.inputs import decode_sparse_depth

    metres = np.arange(1, 81, dtype="<f4")  # 2 rows of 40 float32 pixels: 320 bytes
    msg = TS.types["sensor_msgs/msg/Image"](
        header=image(T0).header,
        height=2,
        width=40,
        encoding="16UC1",  # type: ignore[attr-defined]
        is_bigendian=0,
        step=step,
        data=np.frombuffer(metres.tobytes(), np.uint8),
    )
    with pytest.raises(DataError, match=why):
        decode_sparse_depth(msg, "/d")
