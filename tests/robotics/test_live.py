"""The live Foxglove server (LiveSink) against a real WebSocket client: the messages decoded with the schemas
the server advertises."""

from __future__ import annotations

import base64
import json
import math
import socket
import struct
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from semattnet._errors import InputError, MissingDependencyError
from semattnet.data.frames import Frame, SensorMeta
from semattnet.data.io import read_depth
from semattnet.geometry import RigCalibration, make_T
from semattnet.inference.completer import Completion
from semattnet.inference.sinks import DepthPngSink, Prediction, predict_frame
from semattnet.robotics.bags import CameraInfoData
from semattnet.robotics.live import LiveSink

pytest.importorskip("foxglove")
pytest.importorskip("google.protobuf")
ws_client = pytest.importorskip("websockets.sync.client")
pytestmark = pytest.mark.filterwarnings("ignore:.*hole:UserWarning")  # the frame's holes, on purpose

# The SDK's server speaks foxglove.sdk.v1 (0.30); older ones foxglove.websocket.v1.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
#: The topics of a LiveSink with the default prefix.
TOPICS_ALL = set(LiveSink().topics.values())
H, W = 16, 24
STAMP = 1_317_000_000_123_456_789
K = np.array([[30.0, 0, 11.5], [0, 30.0, 7.5], [0, 0, 1]])
T_CAM_LIDAR = make_T(np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]]), np.array([0.1, -0.2, 0.3]))


def _prediction() -> Prediction:
    """A 16x24 frame with bag-like meta, its completion with holes and a far pixel."""
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    sparse = np.where(rng.random((H, W)) < 0.2, rng.uniform(2, 40, (H, W)), 0).astype(np.float32)
    depth = rng.uniform(1, 60, (H, W)).astype(np.float32)
    depth[0, :5] = 0  # holes
    info = CameraInfoData(
        W,
        H,
        K,
        np.array([0.1, -0.05, 0, 0, 0.01]),
        np.eye(3),
        np.hstack([K, np.zeros((3, 1))]),
        "plumb_bob",
        "cam_info_frame",
    )
    meta = SensorMeta(stamp_ns=STAMP, frame_id="cam_left", lidar_frame_id="velo", camera_info=info)
    calib = RigCalibration(K, T_CAM_LIDAR, (W, H), "left")
    frame = Frame("000042", rgb, sparse, K=K, calib=calib, meta=meta)
    unc = rng.uniform(0, 2, (H, W)).astype(np.float32)
    pred = predict_frame(frame, Completion(depth, uncertainty=unc))
    pred.stage_ms = {"complete": 12.5, "write": 0.25}  # type: ignore[attr-defined]  # optional; the loop adds it
    return pred


def _message_classes(channels: list[dict[str, Any]]) -> dict[int, Any]:
    """Channel id -> the protobuf class of its advertised schema (FileDescriptorSet, base64)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    out = {}
    for ch in channels:
        if ch["encoding"] != "protobuf":
            continue
        pool = descriptor_pool.DescriptorPool()
        fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
        for fd in fds.file:  # dependencies first
            pool.Add(fd)
        out[ch["id"]] = message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))
    return out


def _handshake(ws: Any, topics: set[str]) -> list[dict[str, Any]]:
    """Past serverInfo, with every channel of ``topics`` advertised and subscribed (subscription id = index)."""
    info = json.loads(ws.recv(timeout=5))
    assert info["op"] == "serverInfo" and info["name"] == "semattnet"
    channels: list[dict[str, Any]] = []
    while {c["topic"] for c in channels} != topics:
        msg = json.loads(ws.recv(timeout=5))
        if msg["op"] == "advertise":
            channels += msg["channels"]
    subs = [{"id": i, "channelId": c["id"]} for i, c in enumerate(channels)]
    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
    return channels


def _receive(ws: Any, channels: list[dict[str, Any]], count: int) -> dict[str, tuple[int, Any]]:
    """``count`` messageData frames decoded: topic -> (log time, message or JSON)."""
    classes = _message_classes(channels)
    out = {}
    for _ in range(count):
        data = ws.recv(timeout=5)
        assert isinstance(data, bytes) and data[0] == 0x01  # messageData
        sub, log_time = struct.unpack_from("<IQ", data, 1)
        ch = channels[sub]
        payload = data[13:]
        out[ch["topic"]] = (
            log_time,
            classes[ch["id"]].FromString(payload) if ch["id"] in classes else json.loads(payload),
        )
    return out


def _wait_for(check: Any, what: str) -> None:
    deadline = time.monotonic() + 5
    while not check():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def _refused(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


@pytest.fixture
def sink() -> Iterator[LiveSink]:
    s = LiveSink(address="127.0.0.1:0")
    s.open()
    yield s
    s.abort()


def _stamp_of(msg: Any) -> int:
    return msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos


def _image(msg: Any, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    return np.frombuffer(msg.data, dtype).reshape(shape)


def test_live_frame_round_trip(sink: LiveSink, tmp_path: Path) -> None:
    """Every channel decodes to the frame: depth = the stored PNG (holes NaN), stamps, frame ids, cloud."""
    other = LiveSink(address="127.0.0.1:0")  # a second server in the process: its channels stay its own
    other.open()
    pred = _prediction()
    with ws_client.connect(sink.url, subprotocols=SUBPROTOCOLS, open_timeout=5) as ws:
        channels = _handshake(ws, set(sink.topics.values()))
        assert len(channels) == len(sink.topics) and sink.url == f"ws://127.0.0.1:{sink.port}"
        _wait_for(lambda: all(sink.subscribed(r) for r in sink.topics), "the subscriptions")
        other.write(tmp_path, pred)
        sink.write(tmp_path, pred)
        got = _receive(ws, channels, len(sink.topics))
    other.close()
    assert all(t == STAMP for t, _ in got.values())  # the log time is the sensor stamp
    msgs = {role: got[topic][1] for role, topic in sink.topics.items()}
    for role in ("depth", "uncertainty", "rgb", "sparse", "points", "camera_info"):
        assert _stamp_of(msgs[role]) == STAMP and msgs[role].frame_id == "cam_left", role
    DepthPngSink().write(tmp_path, pred)
    png = read_depth(tmp_path / "000042.png")  # the 16-bit PNG, decode_depth-ed
    holes_nan = np.where(png > 0, png, np.nan)
    d = msgs["depth"]
    assert (d.encoding, d.width, d.height, d.step) == ("32FC1", W, H, W * 4)
    np.testing.assert_array_equal(_image(d, "<f4", (H, W)), holes_nan)
    np.testing.assert_array_equal(_image(d, "<f4", (H, W)), np.where(pred.stored > 0, pred.stored, np.nan))
    u, stored_u = msgs["uncertainty"], pred.uncertainty_stored  # as uncertainty/NAME.png stores it
    assert stored_u is not None and (u.encoding, u.width, u.height, u.frame_id) == ("32FC1", W, H, "cam_left")
    np.testing.assert_array_equal(_image(u, "<f4", (H, W)), np.where(stored_u > 0, stored_u, np.nan))
    assert msgs["rgb"].encoding == "rgb8" and np.array_equal(_image(msgs["rgb"], "u1", (H, W, 3)), pred.frame.rgb)
    sparse = pred.frame.sparse
    np.testing.assert_array_equal(_image(msgs["sparse"], "<f4", (H, W)), np.where(sparse > 0, sparse, np.nan))
    _check_cloud(msgs["points"], pred)
    _check_calibration(msgs["camera_info"], msgs["tf"])
    assert msgs["latency"] == {"frame": "000042", "stamp_ns": STAMP, "stages_ms": {"complete": 12.5, "write": 0.25}}
    port = sink.port
    sink.close()
    _wait_for(lambda: _refused(port), "the server to stop")


def _check_cloud(msg: Any, pred: Prediction) -> None:
    """x, y, z float32 + red, green, blue, alpha uint8 = the coloured completed cloud."""
    offsets = {f.name: f.offset for f in msg.fields}
    assert offsets == {"x": 0, "y": 4, "z": 8, "red": 12, "green": 13, "blue": 14, "alpha": 15}
    assert msg.point_stride == 16
    dtype = np.dtype([("xyz", "<f4", 3), ("rgba", "u1", 4)])
    points = np.frombuffer(msg.data, dtype)
    cloud = pred.cloud(math.inf, 0)
    assert len(points) == int((pred.stored > 0).sum()) == len(cloud.xyz)
    np.testing.assert_array_equal(points["xyz"], cloud.xyz)
    np.testing.assert_array_equal(points["rgba"][:, :3], cloud.rgb)
    assert (points["rgba"][:, 3] == 255).all()


def _check_calibration(calib: Any, tf: Any) -> None:
    """The CameraInfo's K, P, D and size; the camera <- LiDAR transform."""
    from semattnet.robotics.bags.tf import quaternion_to_matrix

    assert (calib.width, calib.height, calib.distortion_model) == (W, H, "plumb_bob")
    np.testing.assert_allclose(np.reshape(calib.K, (3, 3)), K)
    np.testing.assert_allclose(np.reshape(calib.P, (3, 4)), np.hstack([K, np.zeros((3, 1))]))
    np.testing.assert_allclose(calib.D, [0.1, -0.05, 0, 0, 0.01])
    (t,) = tf.transforms
    assert (t.parent_frame_id, t.child_frame_id, _stamp_of(t)) == ("cam_left", "velo", STAMP)
    np.testing.assert_allclose([t.translation.x, t.translation.y, t.translation.z], T_CAM_LIDAR[:3, 3])
    q = t.rotation
    np.testing.assert_allclose(quaternion_to_matrix((q.x, q.y, q.z, q.w)), T_CAM_LIDAR[:3, :3], atol=1e-12)


def test_live_cloud_leaves_out_the_uncertain_pixels(tmp_path: Path) -> None:
    """``max_uncertainty``: the points channel carries exactly the pixels whose stored uncertainty passes."""
    from semattnet.inference.uncertainty import UncertaintyLimit

    limit = UncertaintyLimit(1.0)
    sink = LiveSink(address="127.0.0.1:0", max_uncertainty=limit)
    sink.open()
    pred = _prediction()
    try:
        with ws_client.connect(sink.url, subprotocols=SUBPROTOCOLS, open_timeout=5) as ws:
            channels = _handshake(ws, set(sink.topics.values()))
            _wait_for(lambda: all(sink.subscribed(r) for r in sink.topics), "the subscriptions")
            sink.write(tmp_path, pred)
            got = _receive(ws, channels, len(sink.topics))
    finally:
        sink.abort()
    points = np.frombuffer(got[sink.topics["points"]][1].data, np.dtype([("xyz", "<f4", 3), ("rgba", "u1", 4)]))
    keep = pred.keep(limit)
    assert keep is not None and 0 < keep.sum() < (pred.stored > 0).sum()
    np.testing.assert_array_equal(points["xyz"], pred.cloud(math.inf, 0, limit).xyz)
    assert len(points) == keep.sum()


def test_write_without_client_is_cheap(sink: LiveSink, tmp_path: Path) -> None:
    """No client: nothing is built (not even the cloud) and write returns at once."""
    pred = _prediction()
    start = time.perf_counter()
    for _ in range(20):
        sink.write(tmp_path, pred)
    assert time.perf_counter() - start < 1.0
    assert pred._clouds == {}


def test_close_and_abort_stop_serving(tmp_path: Path) -> None:
    """After close or abort nothing listens on the port; abort never raises (twice, or never opened)."""
    for end in ("close", "abort"):
        s = LiveSink(address="127.0.0.1:0")
        s.open()
        port = s.port
        assert not _refused(port)
        s.close() if end == "close" else s.abort()
        _wait_for(lambda port=port: _refused(port), f"the server to stop after {end}")  # type: ignore[misc]
        s.abort()
    LiveSink().abort()


def test_port_in_use_and_bad_address_are_one_line() -> None:
    """A port in use, an unresolvable host or a malformed address: one-line InputError naming the address."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        address = f"127.0.0.1:{busy.getsockname()[1]}"
        with pytest.raises(InputError, match=address) as e:
            LiveSink(address=address).open()
        assert "\n" not in str(e.value) and "in use" in str(e.value)
    for bad in ("nope", "host:99999", ":8765", "no.such.host.invalid:0"):
        with pytest.raises(InputError, match="live address") as e:
            LiveSink(address=bad).open()
        assert "\n" not in str(e.value) and bad in str(e.value)


def test_missing_foxglove_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without foxglove-sdk: one line with the install hint."""
    monkeypatch.setitem(sys.modules, "foxglove", None)
    with pytest.raises(MissingDependencyError, match=r"pip install 'semattnet\[live\]'") as e:
        LiveSink(address="127.0.0.1:0").open()
    assert "\n" not in str(e.value)


def _ends_within(fn: Any, seconds: float) -> bool:
    """Whether ``fn()`` returns within ``seconds`` (run in a daemon thread: a hang fails the test, not the run);
    what it raises is raised here."""
    import threading

    errors: list[BaseException] = []

    def run() -> None:
        try:
            fn()
        except BaseException as exc:
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    if errors:
        raise errors[0]
    return not thread.is_alive()


def test_half_open_and_idle_clients_do_not_hold_the_server(tmp_path: Path) -> None:
    """60 connections that never send a handshake, then 300 idle ones: close still returns within seconds."""
    sink = LiveSink(address="127.0.0.1:0")
    sink.open()
    socks: list[socket.socket] = []
    try:
        for _ in range(360):
            socks.append(socket.create_connection(("127.0.0.1", sink.port), timeout=5))
        time.sleep(0.2)  # the server (or the gate) has taken them
        assert _ends_within(lambda: sink.close(), 5), "the server did not stop"
    finally:
        for s in socks:
            s.close()
        sink.abort()


def test_a_client_that_never_reads_does_not_hold_the_server(tmp_path: Path) -> None:
    """A subscribed client that stops reading while large frames are logged: write never blocks, close ends."""
    sink = LiveSink(address="127.0.0.1:0")
    sink.open()
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, (256, 512, 3), dtype=np.uint8)
    frame = Frame("big", rgb, np.zeros((256, 512), np.float32), K=K)
    big = predict_frame(frame, Completion(rng.uniform(1, 60, (256, 512)).astype(np.float32)))  # ~3 MiB a frame
    try:
        connect = {"open_timeout": 5, "close_timeout": 0.2, "max_queue": 1}  # it reads no more once one is queued
        with ws_client.connect(sink.url, subprotocols=SUBPROTOCOLS, **connect) as ws:
            _handshake(ws, set(sink.topics.values()))
            _wait_for(lambda: sink.subscribed("depth"), "the subscription")
            assert _ends_within(lambda: [sink.write(tmp_path, big) for _ in range(20)], 10)
            assert _ends_within(lambda: sink.close(), 5)
    finally:
        sink.abort()


def test_a_slow_handshake_is_closed(monkeypatch: pytest.MonkeyPatch) -> None:
    """A client that does not finish its first request in time is closed (the gate's handshake timeout)."""
    from semattnet.robotics import gate

    g = gate.Gate("127.0.0.1", 0, ("127.0.0.1", 9), handshake_s=0.2)
    port = g.start()
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
            s.sendall(b"GET / HTTP/1.1\r\n")
            assert s.recv(1) == b""  # closed by the gate after 0.2 s
    finally:
        g.close()


def test_serving_beyond_loopback_warns_in_one_line() -> None:
    """127.0.0.1: one line, the URL; 0.0.0.0 (every interface): a warning line first."""
    for address, warned in (("127.0.0.1:0", False), ("0.0.0.0:0", True)):
        lines: list[str] = []
        sink = LiveSink(address=address, log=lines.append)
        sink.open()
        sink.abort()
        assert len(lines) == 1 + warned and lines[-1].startswith("live view: ws://")
        assert lines[0].startswith("warning: --live serves ws://0.0.0.0:") == warned, lines
        assert all("\n" not in line for line in lines)
