"""The node's inputs: pairing without waiting a LiDAR period, /tf over /tf_static, and every image accounted for
when the node is fed faster than it completes."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from semattnet.geometry import make_T
from semattnet.inference.contract import Completion
from semattnet.robotics.bags.encode import tf_message
from semattnet.robotics.ros.inputs import KEEP, MAX_TF_FRAMES, Pair, PairingInputs
from semattnet.robotics.ros.node import DepthNode
from semattnet.robotics.ros.status import udp_drops

from ._fakes import T_CAM_LIDAR, TS, FakeTransport, camera_info, image, scan, tf_static

pytest.importorskip("rosbags")

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
TOPICS = {"image": "/img", "scan": "/scan", "camera_info": "/info", "tf_static": "/tf_static", "tf": "/tf"}


def _inputs(max_skew_ns: int | None = None) -> tuple[PairingInputs, list[Pair]]:
    pairs: list[Pair] = []
    return PairingInputs(TOPICS, pairs.append, max_skew_ns=max_skew_ns), pairs


def test_image_after_its_scan_is_paired_at_once_with_kitti_timing() -> None:
    """KITTI: the scan is stamped 10.5 ms before the image, 100 ms apart. With two scans seen (the period known)
    the image is paired when it arrives: the next scan (89.5 ms after it) cannot be nearer."""
    inp, pairs = _inputs()
    for k in range(3):
        inp.on_scan(scan(T0 + k * 100 * MS - 10_500_000))
        inp.on_image(image(T0 + k * 100 * MS))
    # the first image came with one scan only (no period yet): decided when the second scan came
    assert [(p.image.stamp_ns, p.scan.stamp_ns) for p in pairs] == [
        (T0 + k * 100 * MS, T0 + k * 100 * MS - 10_500_000) for k in range(3)
    ]
    assert inp.counts.unpaired == 0 and inp.counts.paired == 3


@pytest.mark.parametrize(
    "offset_ms,at_once",
    [
        (10.5, True),  # 10.5 ms after the last scan, 89.5 ms before the next: decided
        (49.0, True),  # still nearer the last scan, and within the half-period max skew
        (51.0, False),  # the next scan (49 ms away) may be nearer: wait for it
        (70.0, False),
    ],
)
def test_an_image_is_decided_at_once_only_when_the_next_scan_cannot_be_nearer(offset_ms: float, at_once: bool) -> None:
    inp, pairs = _inputs()
    inp.on_scan(scan(T0))
    inp.on_scan(scan(T0 + 100 * MS))
    inp.on_image(image(T0 + 100 * MS + round(offset_ms * MS)))
    assert bool(pairs) is at_once
    if not at_once:
        inp.on_scan(scan(T0 + 200 * MS))
        assert pairs and pairs[0].scan.stamp_ns == T0 + 200 * MS  # the nearer one


def test_at_once_needs_the_max_skew_too() -> None:
    """A tight --max-skew: an image 10 ms after the last scan is not paired at once with 5 ms allowed (the next
    scan is 90 ms away, so it goes unpaired once that comes)."""
    inp, pairs = _inputs(max_skew_ns=5 * MS)
    inp.on_scan(scan(T0))
    inp.on_scan(scan(T0 + 100 * MS))
    inp.on_image(image(T0 + 110 * MS))
    assert not pairs
    inp.on_scan(scan(T0 + 200 * MS))
    assert not pairs and inp.counts.unpaired == 1


def test_dynamic_tf_over_static_newest_per_child_and_bounded() -> None:
    """/tf's newest transform per child frame joins /tf_static's tree; an older one arriving late is ignored."""
    inp, _ = _inputs()
    inp.on_tf_static(tf_message(TS, [("base", "cam", np.eye(4))], 0))
    with pytest.raises(Exception, match="no transform between frames 'velo' and 'cam'"):
        inp.lookup("cam", "velo")
    for stamp, x in ((T0, 1.0), (T0 + 2 * MS, 2.0), (T0 + MS, 9.0)):  # the last is older than the newest
        T = make_T(np.eye(3), np.array([x, 0.0, 0.0]))
        inp.on_tf(tf_message(TS, [("base", "velo", T)], stamp))
    np.testing.assert_allclose(inp.lookup("cam", "velo")[:3, 3], [2.0, 0, 0])
    assert len(inp._dynamic) == 1 and inp.counts.topics["tf"].received == 3
    for i in range(MAX_TF_FRAMES + 5):
        inp.on_tf(tf_message(TS, [("base", f"f{i}", np.eye(4))], T0))
    assert len(inp._dynamic) == MAX_TF_FRAMES and inp.counts.topics["tf"].bad == 6


def test_the_node_uses_tf_when_there_is_no_static_transform() -> None:
    fake = FakeTransport()
    node = DepthNode(fake, _instant, say=[].append).start()
    fake.deliver("/semattnet/input/camera_info", camera_info())
    fake.deliver("/tf", tf_message(TS, [("cam", "velo", T_CAM_LIDAR)], T0))
    fake.deliver("/semattnet/input/point_cloud", scan(T0))
    fake.deliver("/semattnet/input/image", image(T0))
    stop = threading.Event()
    threading.Timer(5.0, stop.set).start()
    node.spin(stop, frames=1)
    stop.set()
    assert node.published == 1


def _instant(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
    return Completion(np.full(sparse.shape, 4.0, np.float32))


def test_fed_faster_than_it_completes_every_image_is_accounted_for() -> None:
    """Images and scans at 1 kHz against a completer taking 20 ms: most pairs go stale, some images are lost
    before pairing (overtaken, or their scan lost), a few fail to decode; received = completed + failed + stale +
    lost + in flight, exactly, while it runs and at the end."""

    def slow(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        time.sleep(0.02)
        return _instant(rgb, sparse)

    fake = FakeTransport()
    lines: list[str] = []
    node = DepthNode(fake, slow, say=lines.append, report_s=0.05).start()
    fake.deliver("/semattnet/input/camera_info", camera_info())
    fake.deliver("/tf_static", tf_static())
    stop = threading.Event()
    worker = threading.Thread(target=node.spin, args=(stop,))
    worker.start()
    sent = 0
    try:
        for k in range(300):
            t = T0 + k * MS
            if k % 7 != 3:  # some images without their scan: lost before pairing
                fake.deliver("/semattnet/input/point_cloud", scan(t))
            bad = k % 50 == 10  # an image that does not decode: its frame fails (if it is taken)
            msg = image(t)
            fake.deliver("/semattnet/input/image", msg if not bad else _truncated(msg))
            sent += 1
            if k % 25 == 0:
                assert node.status().received == sent
            time.sleep(0.001)
    finally:
        time.sleep(0.1)
        stop.set()
        worker.join(10)
    s = node.status()
    assert s.received == sent == 300 and s.accounted, s
    assert s.completed > 0 and s.stale > 0 and s.lost > 0 and s.completed < 100
    assert s.topics["image"].decoded == s.completed + s.failed - s.topics["image"].bad
    assert s.topics["scan"].received == 300 - len([k for k in range(300) if k % 7 == 3])
    final = lines[-1]
    assert final.startswith(f"ros node stopped: {s.completed} frame(s) published, {s.stale} stale pair(s)")
    assert f"{s.lost} image(s) without a scan" in final and "300 image(s) received" in final
    assert f"{s.in_flight} in flight" in final


def _truncated(msg: object) -> object:
    from dataclasses import replace

    return replace(msg, data=msg.data[:10])  # type: ignore[type-var, attr-defined]


def test_udp_drops_reads_this_process_sockets() -> None:
    """A UDP socket of this process flooded past its receive buffer: its drops are counted."""
    import socket
    import sys

    if not sys.platform.startswith("linux"):
        assert udp_drops() is None
        return
    before = udp_drops()
    assert before is not None
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        rx.bind(("127.0.0.1", 0))
        for _ in range(200):
            tx.sendto(b"x" * 1000, rx.getsockname())
        after = udp_drops()
    finally:
        rx.close()
        tx.close()
    assert after is not None and after > before


def test_buffers_are_bounded_and_overflow_counts_as_lost() -> None:
    inp, pairs = _inputs()
    for k in range(KEEP + 3):
        inp.on_image(image(T0 + k * MS))  # no scan ever
    assert inp.waiting == KEEP and inp.counts.unpaired == 3 and not pairs
