"""``semattnet ros2`` / ``ros1``'s options: the one Model section, the domain and the names refused in one line."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from semattnet._errors import InputError
from semattnet.cli import main
from semattnet.cli.ros import ros1, ros2


def test_each_node_takes_the_model_section_and_its_own_transports_options() -> None:
    model = {"weights", "method", "device", "amp", "backend", "precision", "calibration"}
    shared = model | {"segment_spec", "palette_mismatch", "namespace", "image_topic", "live", "rerun_serve"}
    shared |= {"publish", "cloud_stride", "latch_camera_info"}
    assert {p.name for p in ros2.params} >= shared | {"domain_id", "loopback"}
    assert {p.name for p in ros1.params} >= shared | {"master", "host"}
    assert not {p.name for p in ros1.params} & {"domain_id", "loopback"}


@pytest.mark.parametrize(
    "args,env,why",
    [
        (["--method", "classical"], {"ROS_DOMAIN_ID": "lots"}, "ROS_DOMAIN_ID='lots': expected a domain id 0-232"),
        (["--method", "classical", "--domain-id", "300"], {}, "300 is not in the range 0<=x<=232"),
        (["--method", "classical", "--namespace", "/bad name"], {}, "--namespace '/bad name': expected names"),
        (["--method", "classical", "--image-topic", "cam//x y"], {}, "--image-topic 'cam//x y': expected names"),
        ([], {}, "--checkpoint or --weights is required (or --method classical)"),
        (["--method", "classical", "--publish", "depth,cloud"], {}, "--publish 'depth,cloud': expected one or more of"),
        (["--method", "classical", "--cloud-stride", "0"], {}, "--cloud-stride': 0 is not in the range 1<=x"),
        (
            ["--method", "classical", "--points-topic", "/cam/image", "--image-topic", "/cam/image"],
            {},
            "--points-topic /cam/image is also --image-topic: each input needs its own topic",
        ),
        (
            ["--method", "classical", "--image-topic", "~/output/depth_image"],
            {},
            "--image-topic /semattnet/output/depth_image is one of the node's own outputs (--output-prefix)",
        ),
        (
            ["--method", "classical", "--namespace", "/r", "--points-topic", "/r/semattnet/output/point_cloud"],
            {},
            "--points-topic /r/semattnet/output/point_cloud is one of the node's own outputs",
        ),
    ],
)
def test_bad_options_are_one_line(args: list[str], env: dict[str, str], why: str) -> None:
    res = CliRunner().invoke(main, ["ros2", *args], env=env)
    assert res.exit_code in (1, 2) and why in res.output, res.output
    assert "Traceback" not in res.output


def test_ros1_node_name_is_in_its_namespace(monkeypatch: pytest.MonkeyPatch) -> None:
    """ROS 1 names a node by its namespace too (``/robot1/semattnet``): a second robot's node on the same
    master with the same --node-name must not take the first one's name (the master shuts the older down)."""
    from semattnet.robotics.ros import tcpros

    names: list[str] = []

    def transport(master: str, node_name: str, host: str | None = None, **kwargs: object) -> None:
        names.append(node_name)
        raise InputError("stop here")

    monkeypatch.setattr(tcpros, "TcprosTransport", transport)
    res = CliRunner().invoke(
        main, ["ros1", "--method", "classical", "--namespace", "robot1/", "--master", "http://127.0.0.1:9"]
    )
    assert "stop here" in res.output and names == ["/robot1/semattnet"], res.output


@pytest.mark.parametrize(
    "env,loopback",
    [
        ({}, False),
        ({"ROS_LOCALHOST_ONLY": "1"}, True),
        ({"ROS_LOCALHOST_ONLY": "0"}, False),
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, True),
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, False),
    ],
)
def test_ros2_honours_the_localhost_only_environment(
    env: dict[str, str], loopback: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ROS 2 nodes stay on the machine with ROS_LOCALHOST_ONLY=1 (Humble) or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    (Jazzy on): the node's DDS then runs as with --loopback."""
    from semattnet.robotics.ros import dds

    asked: list[bool] = []

    def transport(domain_id: int = 0, loopback: bool = False, **names: str) -> None:
        asked.append(loopback)
        raise InputError("stop here")

    for name in ("ROS_LOCALHOST_ONLY", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(dds, "DdsTransport", transport)
    res = CliRunner().invoke(main, ["ros2", "--method", "classical"], env=env)
    assert "stop here" in res.output and asked == [loopback], res.output
