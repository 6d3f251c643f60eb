"""A bad message of a bag is blamed on itself: every error names the bag, the topic and the message index, and
says what is wrong with that message, not with something downstream that it broke (a scan "with no point in
front of the camera" because the transform was NaN, "K has NaN entries" from the projection).

Three groups, as issue 35 found them: the calibration a ``CameraInfo`` gives, the static transforms of
``/tf_static``, and the LiDAR and semantic messages of a frame. A fault every frame shares (the transform, the
only usable CameraInfo) is one run error; a fault of one message fails only the frames that need it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import DataError
from semattnet.cli import main
from semattnet.robotics import BagSource
from semattnet.robotics.bags import CameraInfoData, MessageWriter, TransformTree
from semattnet.robotics.bags.decode import decode_camera_info
from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.bags.encode import camera_info_message, header, image_message, pointcloud2_message
from semattnet.robotics.bags.reader import message_where
from semattnet.robotics.bags.tf import matrix_to_quaternion

pytest.importorskip("rosbags")

IMAGE, POINTS, INFO, SEMANTIC = "/cam/image", "/lidar", "/cam/camera_info", "/cam/semantic"
H, W, N = 48, 64, 3
T0 = 1_600_000_000 * 10**9
#: LiDAR x forward, y left, z up -> camera x right, y down, z forward, 0.1 m apart.
T_CAM_LIDAR = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0.1], [1, 0, 0, 0], [0, 0, 0, 1]])
Q = matrix_to_quaternion(T_CAM_LIDAR[:3, :3])
Edge = tuple[str, str, Sequence[float], Sequence[float]]  # parent, child, quaternion (x, y, z, w), translation
GOOD_TF: list[Edge] = [("cam", "lidar", Q, (0.0, 0.1, 0.0))]


def _K(fx: float = 50.0) -> np.ndarray:
    return np.array([[fx, 0.0, W / 2], [0.0, 50.0, H / 2], [0.0, 0.0, 1.0]])


def _tf(ts: Any, edges: Sequence[Edge]) -> Any:
    """A ``TFMessage`` of raw numbers (no check, no normalising): what a faulty recorder may write."""
    g = ts.types
    out = []
    for parent, child, (qx, qy, qz, qw), (x, y, z) in edges:
        rot = g["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)
        tr = g["geometry_msgs/msg/Transform"](translation=g["geometry_msgs/msg/Vector3"](x=x, y=y, z=z), rotation=rot)
        out.append(
            g["geometry_msgs/msg/TransformStamped"](header=header(ts, T0, parent), child_frame_id=child, transform=tr)
        )
    return g["tf2_msgs/msg/TFMessage"](transforms=out)


def _points(i: int) -> np.ndarray:
    """(200, 3) float32 points 3 to 20 m ahead of the LiDAR."""
    rng = np.random.default_rng(i)
    return np.column_stack([rng.uniform(3, 20, 200), rng.uniform(-3, 3, 200), rng.uniform(-1, 1, 200)]).astype("f4")


def _cloud(ts: Any, i: int, stamp: int) -> Any:
    p = _points(i)
    return pointcloud2_message(ts, {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]}, stamp, "lidar")


def _bag(
    path: Path,
    *,
    fx: Callable[[int], float] = lambda i: 50.0,
    tf: Sequence[Edge] = GOOD_TF,
    cloud: Callable[[Any, int, int], Any] = _cloud,
    semantic: Callable[[int], np.ndarray] | None = None,
    image_height: Callable[[int], int] = lambda i: H,
    fmt: str = "mcap",
) -> Path:
    """A 3-frame bag in ``fmt`` (10 Hz, each scan 2 ms after its image), a CameraInfo per image with focal length
    ``fx(i)``, ``/tf_static`` of ``tf``, scans ``cloud(ts, i, stamp)``, semantic images ``semantic(i)``, images
    ``image_height(i)`` rows high (the CameraInfo says ``H``)."""
    path = path.with_suffix(".bag") if fmt == "ros1" else path
    with MessageWriter(path, fmt) as out:
        out.write("/tf_static", T0, _tf(out.ts, tf))
        for i in range(N):
            t = T0 + i * 10**8
            K = _K(fx(i))
            info = CameraInfoData(W, H, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam")
            out.write(IMAGE, t, image_message(out.ts, np.full((image_height(i), W, 3), 90 + i, np.uint8), t, "cam"))
            out.write(INFO, t, camera_info_message(out.ts, info, t, "cam"))
            if semantic is not None:
                out.write(SEMANTIC, t, image_message(out.ts, semantic(i), t, "cam"))
            out.write(POINTS, t + 2 * 10**6, cloud(out.ts, i, t + 2 * 10**6))
    return path


def _source(path: Path, **kw: Any) -> BagSource:
    return BagSource(path, IMAGE, POINTS, **kw)


def _outcomes(source: BagSource) -> dict[int, str]:
    """Frame index -> "ok" or its error, loading every frame in order."""
    out = {}
    for i, name in enumerate(source.names):
        try:
            source.load(name)
            out[i] = "ok"
        except DataError as exc:
            out[i] = str(exc)
    return out


def _predict(bag: Path, out: Path, *extra: str) -> Any:
    return CliRunner().invoke(
        main,
        [
            "predict",
            "--bag",
            str(bag),
            "--image-topic",
            IMAGE,
            "--points-topic",
            POINTS,
            "--method",
            "classical",
            "--out",
            str(out),
            *extra,
        ],
    )


def test_the_prefix_names_bag_topic_and_message() -> None:
    assert message_where("/cam/camera_info", 3, "bag.db3") == "bag.db3: /cam/camera_info message 3"
    assert message_where("/cam/image", 7, Path("d.mcap"), "image") == "d.mcap: /cam/image image 7"
    assert message_where("/lidar", 2) == "/lidar message 2"  # inside the error of the frame that needs it


# -- CameraInfo: the focal lengths are checked where the message is decoded ------------------------------------


@pytest.mark.parametrize(
    ("fx", "why"),
    [
        (float("nan"), "focal length fx (K[0][0]) is NaN"),
        (float("inf"), "focal length fx (K[0][0]) is infinite"),
        (1e30, "focal length fx (K[0][0]) is 1e+30 pixels, more than 1000 times the image's 64-pixel side"),
        (-50.0, "focal length fx (K[0][0]) is -50, not positive"),
        (0.0, "focal length fx (K[0][0]) is 0, not positive"),
    ],
)
def test_a_bad_focal_length_in_every_camera_info_is_one_run_error(tmp_path: Path, fx: float, why: str) -> None:
    """Not "K has NaN entries" from the projection nor "no valid depth point" per frame: one line at the start."""
    bag = _bag(tmp_path / "bag", fx=lambda i: fx)
    with pytest.raises(DataError) as err:
        _source(bag)
    assert str(err.value) == f"{bag}: {INFO} message 0: CameraInfo {why}; no image has a usable CameraInfo"


@pytest.mark.parametrize("fmt", ["ros1", "sqlite3", "mcap"])
def test_a_bad_camera_info_fails_only_the_image_nearest_to_it(tmp_path: Path, fmt: str) -> None:
    bag = _bag(tmp_path / "bag", fx=lambda i: float("nan") if i == 1 else 50.0, fmt=fmt)
    got = _outcomes(_source(bag))
    assert got == {
        0: "ok",
        1: f"{bag}: {IMAGE} image 1: {INFO} message 1: CameraInfo focal length fx (K[0][0]) is NaN",
        2: "ok",
    }


@pytest.mark.parametrize("ros1", [True, False])
def test_a_bad_number_elsewhere_in_camera_info_is_named(ros1: bool) -> None:
    K = _K()
    info = CameraInfoData(W, H, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "cam")
    msg = camera_info_message(rosbags_typestore(ros1), info)
    D, P = (msg.D, msg.P) if ros1 else (msg.d, msg.p)
    D[2] = np.inf
    with pytest.raises(DataError, match=r"^X: CameraInfo \(D\[2\]\) is infinite$"):
        decode_camera_info(msg, "X")
    D[2], P[6] = 0.0, np.nan
    with pytest.raises(DataError, match=r"^X: CameraInfo principal point cy \(P\[1\]\[2\]\) is NaN$"):
        decode_camera_info(msg, "X")
    P[6], P[0] = 24.0, 0.0
    with pytest.raises(DataError, match=r"^X: CameraInfo focal length fx \(P\[0\]\[0\]\) is 0, not positive$"):
        decode_camera_info(msg, "X")


def test_the_command_stops_with_one_line_naming_the_camera_info(tmp_path: Path) -> None:
    bag = _bag(tmp_path / "bag", fx=lambda i: float("nan"))
    res = _predict(bag, tmp_path / "out")
    assert res.exit_code == 1, res.output
    assert "skipped" not in res.output and "project_points" not in res.output
    assert f"{bag}: {INFO} message 0: CameraInfo focal length fx (K[0][0]) is NaN" in res.output


# -- /tf_static: each transform checked where it is read; the camera-LiDAR chain must be one ------------------


@pytest.mark.parametrize(
    ("edge", "why"),
    [
        (
            ("cam", "lidar", (0, 0, 0, 0), (0, 0.1, 0)),
            "rotation quaternion (x, y, z, w) = (0, 0, 0, 0) has norm 0; a rotation's has norm 1 (within 0.001)",
        ),
        (
            ("cam", "lidar", (np.nan, 0, 0, 1), (0, 0.1, 0)),
            "rotation quaternion (x, y, z, w) = (nan, 0, 0, 1) is not finite",
        ),
        (("cam", "lidar", Q, (np.nan, 0.1, 0)), "translation (x, y, z) = (nan, 0.1, 0) is not finite"),
        (("cam", "lidar", Q, (0, np.inf, 0)), "translation (x, y, z) = (0, inf, 0) is not finite"),
        (
            ("cam", "lidar", tuple(2 * np.array(Q)), (0, 0.1, 0)),
            "rotation quaternion (x, y, z, w) = (1, -1, 1, 1) has norm 2; a rotation's has norm 1 (within 0.001)",
        ),
    ],
)
def test_a_broken_transform_is_blamed_on_tf_static_not_on_the_scans(tmp_path: Path, edge: Edge, why: str) -> None:
    bag = _bag(tmp_path / "bag", tf=[("base", "cam", (0, 0, 0, 1), (0, 0, 0)), edge])
    with pytest.raises(DataError) as err:
        _source(bag)
    assert str(err.value) == f"{bag}: /tf_static message 0: transform 'cam' -> 'lidar': {why}"


def test_a_quaternion_rounded_in_a_launch_file_is_accepted(tmp_path: Path) -> None:
    c, s = np.cos(np.radians(3.0)), np.sin(np.radians(3.0))
    yawed = T_CAM_LIDAR[:3, :3] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    q = tuple(np.round(matrix_to_quaternion(yawed), 4))  # 4 digits, as typed into a launch file
    assert 0 < abs(np.linalg.norm(q) - 1) < 1e-4
    off = tuple(np.array(Q) * (1 + 5e-4))  # within the 1e-3 tolerance
    for k, quat in enumerate((q, off)):
        bag = _bag(tmp_path / f"bag{k}", tf=[("cam", "lidar", quat, (0, 0.1, 0))])
        assert set(_outcomes(_source(bag)).values()) == {"ok"}


@pytest.mark.parametrize("fmt", ["ros1", "mcap"])
def test_the_command_stops_with_one_line_naming_tf_static(tmp_path: Path, fmt: str) -> None:
    bag = _bag(tmp_path / "bag", tf=[("cam", "lidar", (0, 0, 0, 0), (0, 0.1, 0))], fmt=fmt)
    res = _predict(bag, tmp_path / "out")
    assert res.exit_code == 1, res.output
    assert "no point in front of the camera" not in res.output and "skipped" not in res.output
    assert f"{bag}: /tf_static message 0: transform 'cam' -> 'lidar': rotation quaternion" in res.output


def test_two_disagreeing_chains_between_camera_and_lidar_are_refused(tmp_path: Path) -> None:
    """A cycle: cam -> lidar directly and cam -> base -> lidar 5 m off; none is picked at random."""
    loop = [*GOOD_TF, ("cam", "base", (0, 0, 0, 1), (0, 0, 0)), ("base", "lidar", Q, (5, 0.1, 0))]
    bag = _bag(tmp_path / "bag", tf=loop)
    with pytest.raises(DataError) as err:
        _source(bag)
    assert str(err.value) == (
        f"{bag}: /tf_static: two different transforms from frame 'lidar' to 'cam': lidar -> cam "
        "and lidar -> base -> cam (they differ by 5 m and 0 degrees); the static transforms "
        "must join two frames by one chain"
    )


def test_two_chains_that_agree_are_accepted() -> None:
    tree = TransformTree("T")
    T_cam_base = np.eye(4)
    T_cam_base[:3, 3] = (0.3, 0.0, -1.0)
    tree.add("cam", "lidar", T_CAM_LIDAR)
    tree.add("cam", "base", T_cam_base)
    tree.add("base", "lidar", np.linalg.inv(T_cam_base) @ T_CAM_LIDAR)
    assert np.allclose(tree.lookup("cam", "lidar"), T_CAM_LIDAR)


def test_a_lidar_a_light_year_from_the_camera_is_refused(tmp_path: Path) -> None:
    bag = _bag(tmp_path / "bag", tf=[("cam", "lidar", Q, (0, 1e30, 0))])
    with pytest.raises(DataError) as err:
        _source(bag)
    assert str(err.value) == (
        f"{bag}: /tf_static: the LiDAR frame 'lidar' is 1e+30 m from the camera frame 'cam'; "
        "a camera and a LiDAR of one rig are metres apart"
    )


# -- A frame's scan and semantic image: the frame fails alone, naming the message -------------------------------


def _cloud_with(fault: str) -> Callable[[Any, int, int], Any]:
    """Frame 1's scan with ``fault``: "two_x" (a second field named x), "far" (5 points at 1e30 m), "inf" (every
    point infinite), "padding" (two padding fields named ``_``, as PCL writes them: not a fault)."""

    def cloud(ts: Any, i: int, stamp: int) -> Any:
        p = _points(i)
        if i != 1:
            return _cloud(ts, i, stamp)
        cols = {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]}
        if fault in ("two_x", "padding"):
            cols["second"], cols["third"] = -p[:, 0], p[:, 0]
        if fault == "far":
            cols["x"] = np.where(np.arange(200) < 5, np.float32(1e30), p[:, 0])
        if fault == "inf":
            cols["x"] = np.full(200, np.inf, np.float32)
        msg = pointcloud2_message(ts, cols, stamp, "lidar")
        if fault == "two_x":
            msg.fields[3].name = "x"
        if fault == "padding":
            msg.fields[3].name = msg.fields[4].name = "_"
        return msg

    return cloud


@pytest.mark.parametrize(
    ("fault", "why"),
    [
        (
            "two_x",
            f"{POINTS} message 1: PointCloud2 has 2 fields named 'x' (fields: x, y, z, x, third); which one holds "
            "the values is ambiguous",
        ),
        (
            "far",
            f"{POINTS} message 1: PointCloud2 has 5 of 200 point(s) beyond 1000 m (up to 1e+30 m); a scan is in "
            "metres in the LiDAR's frame (semattnet.robotics.bags.decode.MAX_POINT_COORDINATE_M)",
        ),
        ("inf", f"{POINTS} message 1 (200 point(s) with a NaN or infinite coordinate dropped): no points"),
    ],
)
def test_a_bad_scan_fails_its_frame_alone_naming_it(tmp_path: Path, fault: str, why: str) -> None:
    bag = _bag(tmp_path / "bag", cloud=_cloud_with(fault))
    assert _outcomes(_source(bag)) == {0: "ok", 1: f"{bag}: {IMAGE} image 1: {why}", 2: "ok"}


def test_repeated_padding_fields_are_not_a_fault(tmp_path: Path) -> None:
    bag = _bag(tmp_path / "bag", cloud=_cloud_with("padding"))
    assert set(_outcomes(_source(bag)).values()) == {"ok"}


def test_a_wrong_size_semantic_image_names_bag_topic_and_message(tmp_path: Path) -> None:
    def semantic(i: int) -> np.ndarray:
        return np.zeros((H // 2, W // 2, 3) if i == 1 else (H, W, 3), np.uint8)

    bag = _bag(tmp_path / "bag", semantic=semantic)
    got = _outcomes(_source(bag, semantic_topic=SEMANTIC))
    assert got == {
        0: "ok",
        1: f"{bag}: {IMAGE} image 1: {SEMANTIC} message 1: the semantic image is 32x24, the image 64x48",
        2: "ok",
    }


def test_the_command_skips_the_bad_scan_with_its_name(tmp_path: Path) -> None:
    bag = _bag(tmp_path / "bag", cloud=_cloud_with("two_x"))
    res = _predict(bag, tmp_path / "out")
    assert res.exit_code == 3, res.output
    line = [ln for ln in res.output.splitlines() if ln.startswith("0000000001: skipped: ")]
    assert line == [
        f"0000000001: skipped: {bag}: {IMAGE} image 1: {POINTS} message 1: PointCloud2 has 2 fields "
        "named 'x' (fields: x, y, z, x, third); which one holds the values is ambiguous"
    ]
    assert "3 frame(s): 2 done, 1 skipped" in res.output


def test_an_image_of_another_size_names_the_camera_info_it_disagrees_with(tmp_path: Path) -> None:
    bag = _bag(tmp_path / "bag", image_height=lambda i: 40 if i == 2 else H)
    assert _outcomes(_source(bag)) == {
        0: "ok",
        1: "ok",
        2: f"{bag}: {IMAGE} image 2 is 64x40, the calibration ({INFO} message 2) says 64x48",
    }
