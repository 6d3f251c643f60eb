"""The bag sink (BagWriter) and the Rerun recording read back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet.geometry import make_T
from semattnet.robotics.bags import BagWriter, CameraInfoData, open_bag

pytest.importorskip("rosbags")

K = np.array([[40.0, 0, 7.5], [0, 40.0, 4.5], [0, 0, 1]])
INFO = CameraInfoData(16, 10, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam_in", 5)
STAMPS = [1_317_000_000_123_456_789, 1_317_000_000_223_456_789]


def _depth(i: int) -> np.ndarray:
    d = np.full((10, 16), 4.0 + i, np.float32)
    d[0, :3] = 0  # holes
    d[5, 5] = np.nan
    return d


def _write(path: Path, **kw: object) -> None:
    rgb = np.zeros((10, 16, 3), np.uint8)
    rgb[..., 0] = 200
    rgb[..., 2] = 7
    with BagWriter(path, **kw) as w:  # type: ignore[arg-type]
        for i, t in enumerate(STAMPS):
            w.write(t, "camera_color_left", _depth(i), INFO, rgb=rgb)


@pytest.mark.parametrize("name,fmt", [("out_bag", None), ("out_db3", "sqlite3"), ("out.bag", None)])
def test_bag_writer_round_trip(tmp_path: Path, name: str, fmt: str | None) -> None:
    path = tmp_path / name
    _write(path, fmt=fmt)
    with open_bag(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {
            "/semattnet/depth_image": "sensor_msgs/msg/Image",
            "/semattnet/point_cloud": "sensor_msgs/msg/PointCloud2",
            "/semattnet/camera_info": "sensor_msgs/msg/CameraInfo",
        }
        msgs: dict[str, list] = {}
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            assert t == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            msgs.setdefault(conn.topic, []).append(msg)
    assert {k: len(v) for k, v in msgs.items()} == dict.fromkeys(types, 2)
    for i, (img, cloud, info) in enumerate(zip(*(msgs[t] for t in types), strict=True)):
        for m in (img, cloud, info):
            assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == STAMPS[i]
            assert m.header.frame_id == "camera_color_left"
        assert (img.encoding, img.height, img.width, img.step, img.is_bigendian) == ("32FC1", 10, 16, 64, 0)
        d = np.frombuffer(np.asarray(img.data, np.uint8).tobytes(), "<f4").reshape(10, 16)
        assert np.isnan(d[0, :3]).all() and np.isnan(d[5, 5]) and np.isnan(d).sum() == 4
        assert np.all(d[~np.isnan(d)] == 4.0 + i)
        assert (info.width, info.height) == (16, 10)
        assert [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"] and cloud.width == 160 - 4
        pts = np.frombuffer(
            np.asarray(cloud.data, np.uint8).tobytes(),
            np.dtype(
                {"names": ["z", "rgb"], "formats": ["<f4", "<u4"], "offsets": [8, 12], "itemsize": cloud.point_step}
            ),
        )
        assert np.all(pts["z"] == 4.0 + i)
        assert np.all(pts["rgb"] == (200 << 16) | 7)  # packed as RViz reads it


def test_bag_writer_is_staged_and_refuses_existing(tmp_path: Path) -> None:
    path = tmp_path / "out"
    with pytest.raises(RuntimeError), BagWriter(path) as w:
        w.write(STAMPS[0], "cam", _depth(0), INFO)
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []  # nothing partial left
    _write(path)
    with pytest.raises(FileExistsError, match="out exists; refusing to overwrite"):
        BagWriter(path)
    _write(path, overwrite=True)
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_rerun_recording_loads_back(tmp_path: Path) -> None:
    pytest.importorskip("rerun")
    from semattnet.robotics.rerun import ENTITIES, RerunLogger, read_rrd_frames

    T_cam_lidar = make_T(np.array([[0.0, -1, 0], [0, 0, -1], [1, 0, 0]]), np.array([0.0, -0.1, -0.3]))
    path = tmp_path / "run.rrd"
    rng = np.random.default_rng(0)
    with RerunLogger(path) as log:
        for i, t in enumerate(STAMPS):
            sparse = np.where(_depth(i) > 4.5, 1.0, 0.0)
            log.log_frame(
                t,
                np.zeros((10, 16, 3), np.uint8),
                K,
                T_cam_lidar,
                sparse=sparse,
                depth=_depth(i),
                semantic=rng.integers(0, 19, (10, 16)),
                points=rng.normal(size=(30, 4)),
                uncertainty=_depth(i) / 10,
                keep=_depth(i) > 4.5,
            )
    frames = read_rrd_frames(path)
    for role, entity in ENTITIES.items():
        assert frames[entity] == STAMPS, role
    assert frames["world"] == []  # static view coordinates
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]
    with pytest.raises(FileExistsError):
        RerunLogger(path)
    with pytest.raises(RuntimeError), RerunLogger(tmp_path / "bad.rrd") as log:
        raise RuntimeError("boom")
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]
