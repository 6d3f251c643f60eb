"""The Nav2 / nvblox recipe (docs/guides/nav2.md), as far as this machine goes without ROS 2: the shipped costmap
parameters name the node's cloud, the node's recipe parameters parse, the cloud it publishes with them is one a
voxel layer reads, and the nvblox launch file remaps nvblox's depth inputs onto the node's outputs."""

from __future__ import annotations

import importlib.util
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import semattnet.robotics.ros as ros_package
from semattnet.cli import main
from semattnet.cli import ros as ros_cli
from semattnet.inference.contract import Completion
from semattnet.inference.uncertainty import UncertaintyLimit
from semattnet.robotics.ros.node import DepthNode, NodeTopics

from ._fakes import INFO, FakeTransport, camera_info, image, scan, tf_static
from .test_launch import _stand_ins

pytest.importorskip("rosbags")

LAUNCH = Path(ros_package.__path__[0]) / "launch"
T0 = 1_700_000_000_000_000_000
#: sensor_msgs/PointField's FLOAT32.
FLOAT32 = 7


def _costmap() -> dict[str, Any]:
    doc = yaml.safe_load((LAUNCH / "nav2_costmap.params.yaml").read_text(encoding="utf-8"))
    return doc["local_costmap"]["local_costmap"]["ros__parameters"]  # type: ignore[no-any-return]


@pytest.fixture
def recipe(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The options ``semattnet ros2 --params-file semattnet_nav2.params.yaml`` runs with."""
    got: dict[str, Any] = {}
    monkeypatch.setattr(ros_cli, "_run", lambda params, transport: got.update(params))
    res = CliRunner().invoke(main, ["ros2", "--params-file", str(LAUNCH / "semattnet_nav2.params.yaml")])
    assert res.exit_code == 0, res.output
    return got


def test_the_costmaps_voxel_layer_reads_the_nodes_cloud(recipe: dict[str, Any]) -> None:
    """The observation source is the node's default cloud topic (read from the node, not written again here), a
    PointCloud2 in its own frame, marking and clearing no further than the node's cloud reaches."""
    costmap = _costmap()
    (layer,) = [p for p in costmap["plugins"] if costmap[p]["plugin"] == "nav2_costmap_2d::VoxelLayer"]
    sources = costmap[layer]["observation_sources"].split()
    source = costmap[layer][sources[0]]
    assert source["topic"] == NodeTopics().resolved()["out:points"] == "/semattnet/output/point_cloud"
    assert source["data_type"] == "PointCloud2" and source["sensor_frame"] == ""
    assert source["marking"] is True and source["clearing"] is True
    assert source["obstacle_max_range"] <= source["raytrace_max_range"] <= recipe["max_depth"]
    assert recipe["cloud_stride"] == 4 and recipe["latch_camera_info"] is True
    assert UncertaintyLimit.parse(recipe["max_uncertainty"]) == UncertaintyLimit(0.1, relative=True)
    assert "point_cloud" in recipe["publish"] and "depth_image" in recipe["publish"]


def _uncertain(rgb: np.ndarray, sparse: np.ndarray, semantic: object = None) -> Completion:
    """Depths of 1-9 m; the uncertainty 5 % of the depth, 30 % in the left half (what the gate must drop)."""
    h, w = sparse.shape
    depth = np.tile(np.linspace(1.0, 9.0, w, dtype=np.float32), (h, 1))
    unc = depth * np.float32(0.05)
    unc[:, : w // 2] = depth[:, : w // 2] * np.float32(0.3)
    return Completion(depth, uncertainty=unc)


def test_the_gated_decimated_cloud_has_what_a_voxel_layer_needs(recipe: dict[str, Any]) -> None:
    """With the recipe's --cloud-stride, --max-uncertainty and --max-depth: an unorganised cloud of x, y, z float32
    at offsets 0, 4, 8 (rgb after them), point_step and row_step consistent with the data, dense (no NaN: the holes
    and the gated pixels are left out, not sent as NaN), in the image's frame; exactly the stride grid's pixels whose
    uncertainty is within 10 % of their depth and whose depth is within max_depth."""
    fake = FakeTransport()
    limit = UncertaintyLimit.parse(recipe["max_uncertainty"])
    stride, max_depth = recipe["cloud_stride"], recipe["max_depth"]
    node = DepthNode(fake, _uncertain, say=[].append, cloud_stride=stride, max_uncertainty=limit, max_depth=max_depth)
    node.start()
    for topic, msg in [("camera_info", camera_info()), ("image", image(T0)), ("point_cloud", scan(T0))]:
        fake.deliver(f"/semattnet/input/{topic}", msg)
    fake.deliver("/tf_static", tf_static())
    stop = threading.Event()
    threading.Timer(5.0, stop.set).start()
    node.spin(stop, frames=1)
    stop.set()
    (cloud,) = fake.published[NodeTopics().resolved()["out:points"]]
    c: Any = cloud
    fields = {f.name: (f.offset, f.datatype, f.count) for f in c.fields}
    assert {k: fields[k] for k in "xyz"} == {"x": (0, FLOAT32, 1), "y": (4, FLOAT32, 1), "z": (8, FLOAT32, 1)}
    assert c.height == 1 and c.point_step == 16 and c.row_step == c.point_step * c.width == len(c.data)
    assert c.is_dense is True and not c.is_bigendian and c.header.frame_id == "cam"
    want = _uncertain(np.zeros(0), np.zeros((INFO.height, INFO.width)))
    grid = np.zeros((INFO.height, INFO.width), bool)
    grid[::stride, ::stride] = True
    keep = grid & (want.uncertainty <= 0.1 * want.depth + 1e-6) & (want.depth <= max_depth)  # type: ignore[operator]
    assert 0 < c.width == keep.sum() < grid.sum()
    xyz = np.frombuffer(bytes(c.data), "<f4").reshape(c.width, 4)[:, :3]
    assert np.isfinite(xyz).all() and (xyz[:, 2] <= max_depth + 1e-5).all()


def _nvblox_launch(monkeypatch: pytest.MonkeyPatch) -> tuple[dict[str, str], list[Any]]:
    """The nvblox launch file run against the stand-ins: its declared defaults and its Node actions."""
    for name, module in _stand_ins().items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location("semattnet_nvblox_launch", LAUNCH / "semattnet_nvblox_launch.py")
    assert spec is not None and spec.loader is not None
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    (actions,) = launch_file.generate_launch_description().args
    declared = {a.args[0]: a.kwargs["default_value"] for a in actions if type(a).__name__ == "DeclareLaunchArgument"}
    return declared, [a for a in actions if type(a).__name__ == "Node"]


@pytest.mark.parametrize(("namespace", "node_name"), [("", "semattnet"), ("/robot", "depth"), ("robot", "depth")])
def test_nvblox_is_remapped_onto_the_nodes_depth_and_camera_info(
    monkeypatch: pytest.MonkeyPatch, namespace: str, node_name: str
) -> None:
    declared, (depth, nvblox) = _nvblox_launch(monkeypatch)
    values = {**declared, "namespace": namespace, "node_name": node_name}

    def value(x: object) -> str:
        if isinstance(x, list):
            return "".join(map(value, x))
        return values[x.args[0]] if type(x).__name__ == "LaunchConfiguration" else str(x)  # type: ignore[attr-defined]

    assert nvblox.kwargs["package"] == "nvblox_ros" and nvblox.kwargs["parameters"][0]["use_depth"] is True
    remaps = {a: "/" + value(b).lstrip("/") for a, b in nvblox.kwargs["remappings"]}  # nvblox at the root
    names = NodeTopics().resolved(namespace, node_name)
    assert remaps["camera_0/depth/image"] == remaps["depth/image"] == names["out:depth"]
    assert remaps["camera_0/depth/camera_info"] == remaps["depth/camera_info"] == names["out:camera_info"]
    assert value(depth.kwargs["parameters"][0]).endswith("semattnet_nav2.params.yaml")
    assert value(depth.kwargs["executable"]) == "semattnet" and depth.kwargs["arguments"] == ["ros2"]
