"""``--ros-args``, ROS 1's ``NAME:=VALUE`` words and ROS 2 parameter files on ``semattnet ros2`` / ``ros1``: every
option is a parameter, a wrong key or type is one line naming the file and the key, and who wins is rcl's order
with the command line last."""

from __future__ import annotations

from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.cli import ros as ros_cli
from semattnet.cli._ros_params import settable_params
from semattnet.cli.ros import ros1, ros2


@pytest.fixture
def ran(monkeypatch: pytest.MonkeyPatch) -> dict[str, object]:
    """The options the node would run with (the node itself is not started)."""
    got: dict[str, object] = {}
    monkeypatch.setattr(ros_cli, "_run", lambda params, transport: got.update(params))
    return got


def invoke(args: list[str]) -> str:
    res = CliRunner().invoke(main, args)
    assert "Traceback" not in res.output, res.output
    return res.output if res.exit_code else ""


def write(tmp_path: Path, text: str, name: str = "params.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_launch_files_command_line_names_and_remaps_the_node(ran: dict[str, object], tmp_path: Path) -> None:
    f = write(
        tmp_path,
        "/**:\n  ros__parameters:\n    max_skew: 0.05\n/robot/depth:\n  ros__parameters:\n"
        "    method: classical\n    frames: 7\n",
    )
    args = [
        "ros2",
        "--ros-args",
        "-r",
        "__ns:=/robot",
        "-r",
        "__node:=depth",
        "-p",
        "report_every:=2",
        "--params-file",
        str(f),
        "-r",
        "~/input/image:=/camera/image_raw",
        "--remap",
        "input/x:=/y",
        "-r",
        "/robot/depth/input/point_cloud:=velodyne_points",
        "-r",
        "other:~/input/camera_info:=/x",
        "-r",
        "depth:~/output:=/robot/out",
        "--log-level",
        "warn",
        "--",
    ]
    assert invoke(args) == ""
    assert ran["namespace"] == "/robot" and ran["node_name"] == "depth"
    assert (ran["max_skew"], ran["method"], ran["frames"], ran["report_every"]) == (0.05, "classical", 7, 2.0)
    assert ran["image_topic"] == "/camera/image_raw" and ran["points_topic"] == "/robot/velodyne_points"
    assert ran["camera_info_topic"] == "~/input/camera_info"  # the rule for node "other" is not ours
    assert ran["output_prefix"] == "/robot/out"


def test_who_wins_files_in_order_then_p_then_the_command_line(ran: dict[str, object], tmp_path: Path) -> None:
    a = write(tmp_path, "semattnet:\n  ros__parameters:\n    max_skew: 0.01\n    max_depth: 50.0\n", "a.yaml")
    b = write(tmp_path, "/**:\n  ros__parameters:\n    max_skew: 0.02\n    report_every: 9.0\n", "b.yaml")
    args = [
        "ros2",
        "--params-file",
        str(a),
        "--max-depth",
        "80",
        "--ros-args",
        "--params-file",
        str(b),
        "-p",
        "report_every:=3.0",
        "-p",
        "report_every:=4.0",
    ]
    assert invoke(args) == ""
    assert (ran["max_skew"], ran["max_depth"], ran["report_every"]) == (0.02, 80.0, 4.0)


def test_a_section_for_another_node_does_not_apply(ran: dict[str, object], tmp_path: Path) -> None:
    f = write(
        tmp_path, "other:\n  ros__parameters:\n    max_skew: 0.5\n/*/semattnet:\n  ros__parameters:\n    frames: 2\n"
    )
    assert invoke(["ros2", "--namespace", "r1", "--params-file", str(f)]) == ""
    assert ran["max_skew"] is None and ran["frames"] == 2


def sample(param: click.Parameter, tmp_path: Path) -> object:
    """A value for ``param`` other than its default, of its type."""
    t = param.type
    if param.name == "weights":
        return "semattnet-rt-md-demo-seed0"
    if isinstance(t, click.Choice):
        return next(str(c) for c in t.choices if c != param.default)
    if isinstance(t, click.types.BoolParamType):
        return True
    if isinstance(t, click.Path):
        path = tmp_path / f"{param.name}.json"
        path.write_text("{}", encoding="utf-8")
        return str(path)
    if isinstance(t, click.types.IntParamType):
        return 3
    if t.name == "qos":
        return ["~/output/point_cloud:depth=2"]
    if t.name == "[HOST:]PORT":
        return "127.0.0.1:9999"
    if isinstance(t, click.types.StringParamType):
        return [f"/x/{param.name}"] if param.multiple else f"/x/{param.name}"
    return "25%" if param.name == "max_uncertainty" else 0.25


@pytest.mark.parametrize("command", [ros2, ros1])
def test_every_option_is_settable_from_a_parameter_file(
    command: click.Command, ran: dict[str, object], tmp_path: Path
) -> None:
    params = settable_params(command, click.Context(command, info_name=command.name))
    assert {"image_topic", "namespace", "rig", "max_uncertainty", "weights", "device", "live"} <= set(params)
    values = {name: sample(p, tmp_path) for name, p in params.items() if not p.hidden}  # ros1's --qos: refused
    import yaml

    f = write(tmp_path, yaml.safe_dump({"/**": {"ros__parameters": values}}))
    assert invoke([str(command.name), "--params-file", str(f)]) == ""
    for name, value in values.items():
        got = ran[name]
        if name == "qos":  # the overrides each --qos gave, by the text they came from
            got = tuple(overrides[0].where.removeprefix("--qos ").strip("'") for overrides in got)  # type: ignore[attr-defined]
        got = [str(v) for v in got] if isinstance(got, tuple) else got
        assert got == value or str(got) == str(value), (name, got, value)


@pytest.mark.parametrize(
    "text,why",
    [
        ("semattnet:\n  ros__parameters:\n    max_skw: 0.1\n", "params.yaml: semattnet: max_skw: not a parameter"),
        ("semattnet:\n  ros__parameters:\n    max_skew: fast\n", "params.yaml: semattnet: max_skew: 'fast' is not"),
        ("semattnet:\n  ros__parameters:\n    frames: [1, 2]\n", "params.yaml: semattnet: frames: expected one value"),
        ("semattnet:\n  ros__parameters:\n    method: magic\n", "params.yaml: semattnet: method: 'magic' is not"),
        ("semattnet:\n  ros__parameters:\n    a:\n      b: 1\n", "params.yaml: semattnet: a.b: not a parameter"),
        ("semattnet:\n  max_skew: 0.1\n", "params.yaml: semattnet: expected a mapping holding only ros__parameters"),
        ("[1, 2]\n", "params.yaml: expected NODE_NAME: {ros__parameters"),
        ("a: [\n", "params.yaml: not YAML"),
    ],
)
def test_a_wrong_key_or_type_is_one_line_naming_the_file_and_key(
    text: str, why: str, ran: dict[str, object], tmp_path: Path
) -> None:
    out = invoke(["ros2", "--ros-args", "--params-file", str(write(tmp_path, text))])
    assert why in out and len(out.strip().splitlines()[-1]) > 0 and not ran, out
    assert out.strip().splitlines()[-1].startswith("Error: ")


@pytest.mark.parametrize(
    "args,why",
    [
        (["--ros-args", "--log-config-file", "x"], "--log-config-file is not supported"),
        (["--ros-args", "--qos", "x"], "'--qos' is not an argument this node takes"),
        (["--ros-args", "-p", "max_skew"], "--param 'max_skew': expected NAME:=VALUE"),
        (["--ros-args", "-r", "__foo:=x"], "__foo is not a remap this node takes"),
        (["--ros-args", "-r", "/semattnet/output/depth_image:=/d"], "one output topic cannot be remapped"),
        (["--ros-args", "-p"], "--ros-args: -p needs a value"),
        (["--ros-args", "--log-level", "loud"], "--log-level 'loud': expected one of"),
        (["--ros-args", "-p", "frames:=0"], "-p frames:=0: 0 is not in the range"),
    ],
)
def test_unsupported_ros_arguments_are_refused_in_one_line(args: list[str], why: str, ran: dict[str, object]) -> None:
    out = invoke(["ros2", *args])
    assert why in out and not ran, out


def test_ros1_takes_rosrun_words(ran: dict[str, object]) -> None:
    args = [
        "ros1",
        "__ns:=/robot",
        "__name:=depth",
        "_max_skew:=0.03",
        "~input/image:=/cam/img",
        "__log:=/tmp/x",
        "__master:=http://10.0.0.1:11311",
        "__ip:=10.0.0.2",
    ]
    assert invoke(args) == ""
    assert (ran["namespace"], ran["node_name"], ran["max_skew"]) == ("/robot", "depth", 0.03)
    assert (ran["image_topic"], ran["master"], ran["host"]) == ("/cam/img", "http://10.0.0.1:11311", "10.0.0.2")
    assert "__foo" in invoke(["ros1", "__foo:=1"])
    assert "unexpected extra argument" in invoke(["ros2", "__ns:=/robot"])  # ROS 2 takes them after --ros-args


def test_ros1_reads_roslaunchs_namespace(ran: dict[str, object], monkeypatch: pytest.MonkeyPatch) -> None:
    """roslaunch gives a node's namespace in ROS_NAMESPACE; __ns:= and --namespace win over it, as in rospy."""
    monkeypatch.setenv("ROS_NAMESPACE", "/fleet/r2")
    assert invoke(["ros1"]) == "" and ran["namespace"] == "/fleet/r2"
    assert invoke(["ros1", "__ns:=/r3"]) == "" and ran["namespace"] == "/r3"
    assert invoke(["ros1", "--namespace", "/r4"]) == "" and ran["namespace"] == "/r4"
    assert invoke(["ros2"]) == "" and ran["namespace"] == ""
