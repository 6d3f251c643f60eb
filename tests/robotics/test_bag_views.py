"""A bag's neighbouring frames as views (``BagSource.views``): posed by ``/tf`` over ``/tf_static``, equal to the KITTI
raw drive's own views for a drive written as a bag; no ``/tf`` or no chain: no views, said once; ``/tf`` interpolated
at the image stamps and never extrapolated far; ``adapt --bag`` uses them."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.kitti.raw import RawDrive
from semattnet.data.sources import RawDriveSource
from semattnet.geometry import make_T
from semattnet.robotics import BagSource
from semattnet.robotics.bags import BagTopics, SensorRecord, list_topics, write_kitti_bag, write_sensor_bag
from semattnet.robotics.bags.tf import TransformTree
from semattnet.robotics.bags.tf_buffer import TransformBuffer, interpolate_transform
from semattnet.synthetic.drive import write_synthetic_drives

pytest.importorskip("rosbags")

T = BagTopics.for_camera("02")
NAMES = ["0000000000", "0000000001", "0000000002"]


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A synthetic KITTI raw drive of three 32x64 frames with OXTS poses (1 m forward a frame)."""
    root = tmp_path_factory.mktemp("views")
    write_synthetic_drives(root / "synth", drives=1, frames=3, size=(32, 64), seed=1)
    return next((root / "synth" / "kitti_raw").glob("*/*_sync"))


@pytest.fixture(scope="module")
def bags(drive: Path) -> dict[str, Path]:
    """The drive as a ROS 1 and a ROS 2 (MCAP) bag, by ``write_kitti_bag`` (with /tf), and one without /tf."""
    root = drive.parents[3]
    out = {fmt: write_kitti_bag(drive, root / name, fmt=fmt).path for fmt, name in (("ros1", "d.bag"), ("mcap", "d"))}
    raw = RawDrive(drive, 2)
    recs = [SensorRecord(f.image, f.points, 10**18 + k * 10**8, 10**18 + k * 10**8) for k, f in enumerate(raw)]
    out["no_tf"] = write_sensor_bag(root / "no_tf", recs, raw.calib, fmt="mcap", topics=T).path
    return out


@pytest.mark.parametrize("fmt", ["ros1", "mcap"])
def test_the_views_of_a_kitti_drive_written_as_a_bag_are_the_drives_own(
    bags: dict[str, Path], drive: Path, fmt: str
) -> None:
    assert {r.topic: r.count for r in list_topics(bags[fmt])}["/tf"] == 3  # odom -> base_link, one per frame
    lines: list[str] = []
    source, raw = BagSource(bags[fmt], T.image, T.points, log=lines.append), RawDriveSource(drive)
    got = {name: source.views(name) for name in source.names}
    assert [[v.name for v in got[n]] for n in NAMES] == [NAMES[1:2], [NAMES[0], NAMES[2]], NAMES[1:2]]
    for name in NAMES:
        want = {v.name: v for v in raw.views(name) if v.name != "image_03"}  # the bag has one camera
        assert len(want) == len(got[name])
        for view in got[name]:
            np.testing.assert_allclose(view.T_view_cam, want[view.name].T_view_cam, rtol=0, atol=1e-6)
            assert np.array_equal(view.rgb, want[view.name].rgb) and np.allclose(view.K, want[view.name].K)
    assert np.linalg.norm(got[NAMES[1]][1].T_view_cam[:3, 3]) > 0.5  # the camera moved between the frames
    assert sum("posed by /tf from 'odom' to the camera 'camera_color_left'" in line for line in lines) == 1


def test_a_bag_without_tf_or_without_the_fixed_frame_gives_no_views_said_once(bags: dict[str, Path]) -> None:
    lines: list[str] = []
    source = BagSource(bags["no_tf"], T.image, T.points, log=lines.append)
    assert all(source.views(name) == () for name in source.names)
    assert [line for line in lines[1:]] == [f"{bags['no_tf']}: /tf: no transform; the frames get no neighbouring views"]
    lines.clear()
    source = BagSource(bags["mcap"], T.image, T.points, log=lines.append, odom_frame="map")  # adapt --odom-frame map
    assert all(source.views(name) == () for name in source.names)
    assert len(lines) == 2 and "no chain from 'map' to the camera frame 'camera_color_left'" in lines[1]
    assert "/tf frames: base_link, odom" in lines[1]


def _rotation_angle(T: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1, 1)))


def test_tf_is_interpolated_half_way_and_not_extrapolated_beyond_the_tolerance() -> None:
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 degrees about z
    static = TransformTree()
    static.add("base", "cam", make_T(np.eye(3), np.array([0.0, 0, 1.5])))
    buffer = TransformBuffer(static, tolerance_s=0.01)
    buffer.add("odom", "base", 2 * 10**9, make_T(Rz, np.array([2.0, 4, 0])))  # in any order
    buffer.add("odom", "base", 10**9, np.eye(4))
    half = buffer.at("odom", "base", 1_500_000_000)
    assert half is not None
    np.testing.assert_allclose(half[:3, 3], [1, 2, 0], atol=1e-12)
    assert _rotation_angle(half) == pytest.approx(np.pi / 4, abs=1e-12) and half[1, 0] > 0  # about +z
    quarter = buffer.lookup("odom", "cam", 1_250_000_000)  # chained with the static edge
    assert quarter is not None and _rotation_angle(quarter) == pytest.approx(np.pi / 8, abs=1e-12)
    np.testing.assert_allclose(quarter[:3, 3], [0.5, 1, 1.5], atol=1e-12)
    near = buffer.at("odom", "base", 2_005_000_000)  # 5 ms past the last sample: within the tolerance
    assert near is not None and near[0, 3] == pytest.approx(2.01)
    for stamp in (2_020_000_000, 980_000_000):  # 20 ms outside: refused
        assert buffer.at("odom", "base", stamp) is None and buffer.lookup("odom", "cam", stamp) is None
    one = interpolate_transform(np.array([5]), np.zeros((1, 3)), np.array([[0.0, 0, 0, 1]]), 7, tolerance_ns=1)
    assert one is None
    buffer.add("odom", "base", 2 * 10**9, make_T(Rz, np.array([4.0, 4, 0])))  # the same stamp again: the last wins
    later = buffer.at("odom", "base", 1_500_000_000)
    assert later is not None and later[0, 3] == pytest.approx(2.0)


def test_a_neighbour_outside_the_span_of_tf_is_no_view(drive: Path, tmp_path: Path) -> None:
    """/tf covers the first two frames only: the second frame has its previous neighbour alone, the third none."""
    raw = RawDrive(drive, 2)
    recs = [
        SensorRecord(
            f.image,
            f.points,
            10**18 + k * 10**8,
            10**18 + k * 10**8,
            pose=make_T(np.eye(3), np.array([k, 0.0, 0])) if k < 2 else None,
        )
        for k, f in enumerate(raw)
    ]
    bag = write_sensor_bag(tmp_path / "part", recs, raw.calib, fmt="mcap", topics=T).path
    source = BagSource(bag, T.image, T.points)
    assert [[v.name for v in source.views(n)] for n in NAMES] == [NAMES[1:2], NAMES[:1], []]


def _adapt(bag: Path, weights: Path, out: Path, *extra: str) -> Any:
    args = [
        "adapt",
        "--bag",
        bag,
        "--image-topic",
        T.image,
        "--points-topic",
        T.points,
        "--weights",
        weights,
        "--out",
        out,
        "--crop",
        "32x64",
        "--batch-size",
        "1",
        "--steps",
        "1",
        "--device",
        "cpu",
    ]
    return CliRunner().invoke(main, list(map(str, [*args, *extra])))


@pytest.mark.filterwarnings("ignore:no semantic maps given")
@pytest.mark.parametrize(
    ("bag", "photometric"),
    [
        ("mcap", True),
        pytest.param("no_tf", False, marks=pytest.mark.slow),  # seconds; the source's own test above is fast
    ],
)
def test_adapt_on_a_bag_uses_its_neighbouring_frames_where_tf_poses_them(
    bags: dict[str, Path], tiny_weights: Path, tmp_path: Path, bag: str, photometric: bool
) -> None:
    res = _adapt(bags[bag], tiny_weights, tmp_path / "run", *(["--odom-frame", "odom"] if photometric else []))
    assert res.exit_code == 0, res.output
    assert res.output.count("posed by /tf from 'odom'") == int(photometric)
    step = json.loads((tmp_path / "run" / "log.json").read_text())["steps"][0]
    assert ("photometric" in step and step["photometric"] > 0) is photometric
    assert res.output.count("no other view") == (0 if photometric else 1)
    assert res.output.count("no neighbouring views") == (0 if photometric else 1)


def _stamped(parent: str, child: str, sec: int, x: float, w: float) -> SimpleNamespace:
    vec, rot = SimpleNamespace(x=x, y=0.0, z=0.0), SimpleNamespace(x=0.0, y=0.0, z=0.0, w=w)
    header = SimpleNamespace(frame_id=parent, stamp=SimpleNamespace(sec=sec, nanosec=0))
    transform = SimpleNamespace(translation=vec, rotation=rot)
    return SimpleNamespace(header=header, child_frame_id=child, transform=transform)


def test_a_bad_tf_transform_is_left_out_and_kept_to_be_said() -> None:
    buffer = TransformBuffer()
    msg = SimpleNamespace(
        transforms=[
            _stamped("/odom", "base", 1, 1.0, 1.0),
            _stamped("odom", "base", 2, np.nan, 1.0),
            _stamped("odom", "base", 3, 3.0, 0.5),
        ]
    )
    buffer.add_message(msg, "b.mcap: /tf message 0")
    assert list(buffer.tracks[("odom", "base")].stamps) == [10**9]
    assert len(buffer.skipped) == 2
    assert buffer.skipped[0].startswith("b.mcap: /tf message 0: transform 'odom' -> 'base': ")
    assert "not finite" in buffer.skipped[0] and "norm 0.5" in buffer.skipped[1]
