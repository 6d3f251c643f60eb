"""QoS overrides per topic: rclcpp's ``qos_overrides`` parameters and ``--qos``, applied to the node's DDS
readers and writers (matched or not as the DDS rules say), refused in one line when wrong; ROS 1 has none."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.cli import ros as ros_cli
from semattnet.robotics.ros.node import DepthNode, NodeTopics
from semattnet.robotics.ros.qos import default_qos, node_qos
from semattnet.robotics.ros.transport import OUTPUT_QOS, SENSOR_QOS, QoS

PARAMS = """\
/**:
  ros__parameters:
    method: classical
    qos_overrides:
      /camera/image_raw:
        subscription:
          reliability: reliable
          depth: 10
      /robot/depth/output/point_cloud:
        publisher:
          reliability: best_effort
          durability: volatile
          history: keep_last
"""


@pytest.fixture
def ran(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    got: dict[str, Any] = {}
    monkeypatch.setattr(ros_cli, "_run", lambda params, transport: got.update(params))
    return got


def _qos(params: dict[str, Any]) -> dict[str, QoS]:
    names = NodeTopics(params["image_topic"], output=params["output_prefix"]).resolved("/robot", "depth")
    return node_qos([o for given in params["qos"] for o in given], names, "/robot", "depth")


def test_a_params_files_qos_overrides_name_the_remapped_topics_and_the_command_line_wins(
    tmp_path: Path, ran: dict[str, Any]
) -> None:
    """rclcpp's nested ``qos_overrides`` keys, named by the topic after remapping; ``--qos`` after them wins."""
    params = tmp_path / "p.yaml"
    params.write_text(PARAMS, encoding="utf-8")
    args = ["ros2", "--qos", "~/output/point_cloud:depth=3", "--ros-args", "-r", "__ns:=/robot", "-r", "__node:=depth"]
    args += ["-r", "~/input/image:=/camera/image_raw", "--params-file", str(params)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    qos = _qos(ran)
    assert qos["image"] == QoS(reliable=True, depth=10) and qos["scan"] == SENSOR_QOS
    assert qos["out:points"] == QoS(reliable=False, depth=3) and qos["out:depth"] == OUTPUT_QOS
    res = CliRunner().invoke(main, [*args, "-p", "qos_overrides./robot/depth/output/point_cloud.publisher.depth:=7"])
    assert res.exit_code == 0 and _qos(ran)["out:points"].depth == 3  # the command line's --qos still wins


def test_defaults_unchanged() -> None:
    qos = default_qos()
    assert qos["image"] == qos["scan"] == qos["camera_info"] == SENSOR_QOS
    assert {qos[f"out:{r}"] for r in ("depth", "points", "uncertainty", "camera_info")} == {OUTPUT_QOS}
    assert default_qos(latch_camera_info=True)["out:camera_info"].durable


@pytest.mark.parametrize(
    ("command", "file", "why"),
    [
        (
            "ros2",
            "/x:\n  publisher:\n    reliability: maybe",
            "/**: qos_overrides./x.publisher.reliability: reliability",
        ),
        ("ros2", "/x:\n  publisher:\n    liveliness: automatic", "'liveliness' is not a QoS policy this node takes"),
        ("ros2", "/x:\n  writer:\n    depth: 1", "expected qos_overrides.TOPIC.publisher|subscription.POLICY"),
        ("ros2", "/x:\n  publisher:\n    history: keep_all", "history keep_all: not taken"),
        ("ros2", "/x:\n  publisher:\n    depth: 1", "qos_overrides./x.publisher.depth: /x is not one of the node's"),
        ("ros2", "/tf:\n  publisher:\n    depth: 1", "the node has a subscription on /tf, not a publisher"),
        ("ros1", "/tf:\n  subscription:\n    depth: 1", "qos_overrides./tf.subscription.depth: ROS 1 has no QoS"),
    ],
)
def test_a_wrong_override_is_refused_in_one_line_naming_file_section_and_key(
    tmp_path: Path, command: str, file: str, why: str
) -> None:
    params = tmp_path / "p.yaml"
    body = "\n".join("      " + line for line in file.splitlines())
    params.write_text(f"/**:\n  ros__parameters:\n    method: classical\n    qos_overrides:\n{body}\n", "utf-8")
    res = CliRunner().invoke(main, [command, "--params-file", str(params)])
    line = res.output.strip().splitlines()[-1]
    assert res.exit_code in (1, 2) and str(params) in line and why in line, res.output
    assert "Traceback" not in res.output


@pytest.mark.parametrize(
    ("command", "qos", "why"),
    [
        ("ros2", "~/input/image:reliability=sometimes", "reliability 'sometimes': expected one of reliable"),
        ("ros2", "~/input/image:depth=0", "depth '0': expected a positive number"),
        ("ros2", "image", "expected TOPIC:POLICY=VALUE"),
        ("ros1", "~/input/image:depth=2", "ROS 1 has no QoS"),
    ],
)
def test_a_wrong_qos_option_is_one_line(command: str, qos: str, why: str) -> None:
    res = CliRunner().invoke(main, [command, "--method", "classical", "--qos", qos])
    assert res.exit_code == 2 and why in res.output and "Traceback" not in res.output, res.output


def _matched(entities: dict[str, Any], status: str, want: dict[str, int]) -> dict[str, int]:
    """Each entity's matched count: as soon as they are ``want`` (then again 0.3 s later: nothing more matched),
    else after 5 s (discovery over loopback takes well under a second)."""
    counts: dict[str, int] = {}
    for _ in range(50):
        counts = {k: getattr(e, status)().current_count for k, e in entities.items()}
        if counts == want:
            time.sleep(0.3)
            return {k: getattr(e, status)().current_count for k, e in entities.items()}
        time.sleep(0.1)
    return counts


def test_overridden_qos_is_what_dds_peers_match() -> None:
    """A best-effort depth_image writer matches a best-effort reader, not a reliable one; a reliable image reader
    matches a reliable writer, not a best-effort one; a transient-local reader matches the camera_info writer made
    transient local, not the point cloud's (volatile, the default)."""
    pytest.importorskip("cyclonedds")
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from semattnet.robotics.ros.dds import DdsTransport

    transport = DdsTransport(45, loopback=True)
    names = NodeTopics().resolved()
    overrides = ros_cli.QosType().convert("~/output/depth_image:reliability=best_effort", None, None)
    overrides += ros_cli.QosType().convert("~/input/image:reliability=reliable", None, None)
    overrides += ros_cli.QosType().convert("~/output/camera_info:durability=transient_local", None, None)
    node = DepthNode(transport, lambda *a: None, qos=node_qos(overrides, names), say=[].append)  # type: ignore[arg-type]
    node.start()
    peer = DomainParticipant(45)
    image_t, info_t = (transport._types.struct(f"sensor_msgs/msg/{t}", raw=True) for t in ("Image", "CameraInfo"))
    cloud_t = transport._types.struct("sensor_msgs/msg/PointCloud2", raw=True)
    P = Policy

    def qos(reliable: bool, durable: bool = False) -> Qos:
        r = P.Reliability.Reliable(0) if reliable else P.Reliability.BestEffort
        return Qos(r, P.Durability.TransientLocal if durable else P.Durability.Volatile, P.History.KeepLast(1))

    def topic(role: str, cls: type) -> Topic:
        return Topic(peer, "rt" + names[role], cls)

    try:
        depth, image = topic("out:depth", image_t), topic("image", image_t)
        readers = {
            "depth reliable": DataReader(peer, depth, qos=qos(True)),
            "depth best effort": DataReader(peer, depth, qos=qos(False)),
            "info transient local": DataReader(peer, topic("out:camera_info", info_t), qos=qos(True, True)),
            "cloud transient local": DataReader(peer, topic("out:points", cloud_t), qos=qos(True, True)),
        }
        writers = {"image best effort": DataWriter(peer, image, qos=qos(False))}
        writers["image reliable"] = DataWriter(peer, image, qos=qos(True))
        want = {"depth reliable": 0, "depth best effort": 1, "info transient local": 1, "cloud transient local": 0}
        assert _matched(readers, "get_subscription_matched_status", want) == want
        want = {"image best effort": 0, "image reliable": 1}
        assert _matched(writers, "get_publication_matched_status", want) == want
    finally:
        node.close()
        peer.__del__()
