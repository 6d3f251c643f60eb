"""``semattnet predict --bag``: byte-identical to ``--kitti-raw``; ``--bag-out``, ``--rerun`` read back; bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.kitti.raw import RawDrive
from semattnet.geometry import read_kitti_calibration
from semattnet.robotics.bags import BagTopics, SensorRecord, open_bag, write_sensor_bag
from tests.inference._raw_sample import DRIVE, RAW_DATE

pytest.importorskip("rosbags")

T0 = 1_317_000_000 * 10**9 + 987_654_321
FORMATS = {"ros1": "drive.bag", "sqlite3": "drive_db3", "mcap": "drive_mcap"}
T = BagTopics()
TOPICS = ["--image-topic", T.image, "--points-topic", T.points]


@pytest.fixture(scope="module")
def sample(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two-frame bags (0.1 s apart, NaN points, intermediate tf frame), the KITTI rig JSON and the --kitti-raw run."""
    frame = RawDrive(DRIVE, 2).frame("0000000005")
    root = tmp_path_factory.mktemp("bags")
    recs = [SensorRecord(frame.image, frame.points, T0 + i * 10**8, T0 + i * 10**8 + 2 * 10**6) for i in range(2)]
    imu = read_kitti_calibration(RAW_DATE, "02")
    out = {fmt: root / name for fmt, name in FORMATS.items()}
    for fmt, path in out.items():
        write_sensor_bag(path, recs, frame.calib, fmt=fmt, nan_points=25, T_base_lidar=imu.T_cam0_lidar)
    cal = read_kitti_calibration(RAW_DATE, "02")
    out["rig"] = root / "kitti_rig.json"
    out["rig"].write_text(
        json.dumps({"K": cal.K.tolist(), "T_cam_lidar": cal.T_cam_lidar.tolist(), "image_size": list(cal.image_size)})
    )
    out["raw"] = root / "raw"
    res = CliRunner().invoke(
        main, ["predict", "--kitti-raw", str(DRIVE), "--method", "classical", "--out", str(out["raw"])]
    )
    assert res.exit_code == 0, res.output
    return out


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_bag_gives_byte_identical_depth_pngs_to_kitti_raw(sample: dict[str, Path], fmt: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = CliRunner().invoke(
        main,
        [
            "predict",
            "--bag",
            str(sample[fmt]),
            *TOPICS,
            "--rig",
            str(sample["rig"]),
            "--method",
            "classical",
            "--out",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "2 image(s) paired with a scan within 50.0 ms, 0 dropped" in res.output
    want = (sample["raw"] / "0000000005.png").read_bytes()
    for name in ("0000000000", "0000000001"):
        assert (out / f"{name}.png").read_bytes() == want
        assert (out / f"{name}_color.png").read_bytes() == (sample["raw"] / "0000000005_color.png").read_bytes()
    assert "read/decode" in res.output and "projection" in res.output and "sensor period of 100.0 ms" in res.output
    assert json.loads((out / "latency.json").read_text())["frames"] == 2


def test_bag_out_and_rerun_read_back(sample: dict[str, Path], tmp_path: Path) -> None:
    from PIL import Image

    bag_out, rrd, out = tmp_path / "pred_mcap", tmp_path / "run.rrd", tmp_path / "out"
    args = ["--out", str(out), "--bag-out", str(bag_out), "--rerun", str(rrd), "--stream"]
    res = CliRunner().invoke(main, ["predict", "--bag", str(sample["mcap"]), *TOPICS, "--method", "classical", *args])
    assert res.exit_code == 0, res.output
    assert "(read ahead)" in res.output
    with open_bag(sample["mcap"]) as reader:  # the input's header stamps and frame ids
        heads = [
            (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.header.frame_id)
            for c, _, raw in reader.messages([c for c in reader.connections if c.topic == T.image])
            for m in [reader.deserialize(raw, c.msgtype)]
        ]
    with open_bag(bag_out) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        msgs: dict[str, list] = {}
        for conn, _, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    assert types == {
        "/semattnet/depth_image": "sensor_msgs/msg/Image",
        "/semattnet/point_cloud": "sensor_msgs/msg/PointCloud2",
        "/semattnet/camera_info": "sensor_msgs/msg/CameraInfo",
    }
    assert {k: len(v) for k, v in msgs.items()} == dict.fromkeys(types, 2)
    for i, (img, cloud, info) in enumerate(zip(*(msgs[t] for t in types), strict=True)):
        for m in (img, cloud, info):
            assert (m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, m.header.frame_id) == heads[i]
        assert (img.encoding, img.width, img.height, info.width, info.height) == ("32FC1", 1242, 375, 1242, 375)
        depth = np.frombuffer(np.asarray(img.data, np.uint8).tobytes(), "<f4").reshape(375, 1242)
        png = np.asarray(Image.open(out / f"{i:010d}.png")).astype(np.float32)
        assert np.array_equal(np.isnan(depth), png == 0)  # holes NaN
        assert np.array_equal(depth[png > 0], png[png > 0] / 256.0)  # the depth as the PNG stores it
        assert cloud.width > 0 and [f.name for f in cloud.fields] == ["x", "y", "z", "rgb"]
    assert heads[1][0] - heads[0][0] == 10**8
    pytest.importorskip("rerun")
    from semattnet.robotics.rerun import ENTITIES, read_rrd_frames

    frames = read_rrd_frames(rrd)
    for role, entity in ENTITIES.items():
        if role not in ("semantic", "uncertainty"):  # classical needs no semantic map; no --uncertainty given
            assert frames[entity] == [h[0] for h in heads], role


def _invoke(args: list[str]):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["predict", *args])


def test_bad_input_is_one_line_and_leaves_nothing(sample: dict[str, Path], tmp_path: Path) -> None:
    bag, out = str(sample["ros1"]), tmp_path / "out"
    base = ["--bag", bag, "--method", "classical", "--out", str(out)]
    cases = [
        ([*base, "--image-topic", "/nope", "--points-topic", T.points], "no topic '/nope'"),
        ([*base, "--image-topic", T.image, "--points-topic", T.image], "holds sensor_msgs/msg/Image"),
        ([*base, *TOPICS, "--max-skew", "0.001"], "scan within 1.0 ms"),
        ([*base, *TOPICS, "--bag-out", bag], "would replace the input"),
        ([*base, *TOPICS, "--bag-out", str(tmp_path)], "would replace the output folder"),
        ([*base, *TOPICS, "--semantic-topic", "/kitti/none"], "no topic '/kitti/none'"),
    ]
    for args, message in cases:
        res = _invoke(args)
        assert res.exit_code == 1 and message in res.output, (args, res.output)
        assert len(res.output.strip().splitlines()) <= 2, res.output  # the pairing report, then the error
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    res = _invoke(["--bag", bag, "--method", "classical", "--out", str(out)])
    assert res.exit_code == 2 and "--image-topic and --points-topic" in res.output
    res = _invoke(["--rgb", bag, "--sparse", bag, "--image-topic", T.image, "--out", str(out)])
    assert res.exit_code == 2 and "--image-topic is an option of --bag, not of --rgb" in res.output
    res = _invoke([*base, *TOPICS, "--semantic-topic", T.image, "--segment", "x"])
    assert res.exit_code == 2 and "--semantic-topic or --segment, not both" in res.output
    res = _invoke(["--bag", bag, "--list-topics"])
    assert res.exit_code == 0 and "sensor_msgs/msg/PointCloud2" in res.output
    (tmp_path / "exists.rrd").write_text("x")
    res = _invoke([*base, *TOPICS, "--rerun", str(tmp_path / "exists.rrd")])
    assert res.exit_code == 1 and "exists.rrd exists" in res.output and not out.exists()


def test_failed_frame_leaves_no_bag_and_no_recording(sample: dict[str, Path], tmp_path: Path) -> None:
    from semattnet.inference.pipeline import RunOptions, check_frames
    from semattnet.inference.sinks import default_sinks
    from semattnet.robotics import BagSource
    from semattnet.robotics.sinks import BagSink, RerunSink

    pytest.importorskip("rerun")
    calls = []

    from semattnet.baselines.classical import ClassicalCompleter

    class Failing(ClassicalCompleter):
        def __call__(self, rgb, sparse, semantic=None):  # type: ignore[no-untyped-def]
            calls.append(1)
            if len(calls) == 2:
                raise RuntimeError("frame 2 fails")
            return super().__call__(rgb, sparse, semantic)

    failing = Failing()

    sinks = [*default_sinks(), BagSink(target=tmp_path / "b.bag"), RerunSink(target=tmp_path / "r.rrd")]
    source = BagSource(sample["sqlite3"], T.image, T.points, rig=sample["rig"])
    with pytest.raises(RuntimeError, match="frame 2 fails"):
        check_frames(source, sinks, tmp_path / "out", options=RunOptions(prefetch=2)).run(failing, log=lambda _: None)
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no bag, no recording, nothing staged beside them
    first = source.names[0]  # the frame done before the error stays, whole and journaled (resumable)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [f"{first}.png", f"{first}_color.png", "frames.json"]
