"""The launch file, the example parameter file and the example systemd unit shipped with the package, checked
without ROS: the launch file run against small stand-ins of ``launch`` / ``launch_ros`` that record its actions,
the command ``launch_ros.actions.Node`` would build from them (as its Humble source builds it) and the unit's
``ExecStart`` both parsed by ``semattnet ros2`` itself."""

from __future__ import annotations

import importlib.util
import shlex
import sys
import types
from pathlib import Path

import pytest
from click.testing import CliRunner

import semattnet.robotics.ros as ros_package
from semattnet.cli import main
from semattnet.cli import ros as ros_cli

LAUNCH = Path(ros_package.__path__[0]) / "launch"


class _Recorded:
    """A stand-in action or substitution: its arguments."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.args, self.kwargs = args, kwargs


def _stand_ins() -> dict[str, types.ModuleType]:
    modules = {name: types.ModuleType(name) for name in ("launch", "launch.actions", "launch.substitutions")}
    modules |= {name: types.ModuleType(name) for name in ("launch_ros", "launch_ros.actions")}
    for module, names in (
        ("launch", ["LaunchDescription"]),
        ("launch.actions", ["DeclareLaunchArgument"]),
        ("launch.substitutions", ["LaunchConfiguration"]),
        ("launch_ros.actions", ["Node"]),
    ):
        for name in names:
            setattr(modules[module], name, type(name, (_Recorded,), {}))
    return modules


@pytest.fixture
def ran(monkeypatch: pytest.MonkeyPatch) -> dict[str, object]:
    got: dict[str, object] = {}
    monkeypatch.setattr(ros_cli, "_run", lambda params, transport: got.update(params))
    return got


def _node_command(monkeypatch: pytest.MonkeyPatch, given: dict[str, str]) -> list[str]:
    """The command launch_ros' Node would run for the launch file with the launch arguments ``given``."""
    for name, module in _stand_ins().items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location("semattnet_depth_launch", LAUNCH / "semattnet_depth_launch.py")
    assert spec is not None and spec.loader is not None
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    description = launch_file.generate_launch_description()
    (actions,) = description.args
    declared = {a.args[0]: a.kwargs["default_value"] for a in actions if type(a).__name__ == "DeclareLaunchArgument"}
    values = {**declared, **given}
    (node,) = [a for a in actions if type(a).__name__ == "Node"]
    assert "package" not in node.kwargs  # so Node runs the executable from PATH (module doc)

    def value(x: object) -> str:
        return values[x.args[0]] if type(x).__name__ == "LaunchConfiguration" else str(x)  # type: ignore[attr-defined]

    k = node.kwargs
    namespace = "/" + value(k["namespace"]).strip("/")
    cmd = [value(k["executable"]), *map(value, k["arguments"]), "--ros-args", "-r", f"__node:={value(k['name'])}"]
    cmd += ["-r", f"__ns:={namespace}"] + [a for p in k["parameters"] for a in ("--params-file", value(p))]
    return cmd


def test_the_launch_files_node_command_is_taken_by_ros2(
    monkeypatch: pytest.MonkeyPatch, ran: dict[str, object]
) -> None:
    cmd = _node_command(monkeypatch, {"namespace": "robot", "node_name": "depth"})
    assert cmd[:2] == ["semattnet", "ros2"] and cmd[-1].endswith("semattnet_depth.params.yaml")
    res = CliRunner().invoke(main, cmd[1:])
    assert res.exit_code == 0, res.output
    assert (ran["namespace"], ran["node_name"]) == ("/robot", "depth")
    assert (ran["image_topic"], ran["method"], ran["max_skew"]) == ("/camera/image_raw", "classical", 0.05)


def test_the_launch_file_with_its_defaults(monkeypatch: pytest.MonkeyPatch, ran: dict[str, object]) -> None:
    cmd = _node_command(monkeypatch, {})
    assert "__ns:=/" in cmd
    assert CliRunner().invoke(main, cmd[1:]).exit_code == 0
    assert (ran["namespace"], ran["node_name"]) == ("/", "semattnet")


def test_the_example_systemd_units_command_is_taken_by_ros2(ran: dict[str, object]) -> None:
    unit = (LAUNCH / "semattnet-depth.service").read_text(encoding="utf-8")
    (exec_start,) = [line for line in unit.splitlines() if line.startswith("ExecStart=")]
    argv = shlex.split(exec_start.removeprefix("ExecStart="))
    assert argv[0].endswith("/bin/semattnet") and "KillSignal=SIGTERM" in unit
    argv = [str(LAUNCH / "semattnet_depth.params.yaml") if a == "/etc/semattnet/depth.yaml" else a for a in argv]
    res = CliRunner().invoke(main, argv[1:])
    assert res.exit_code == 0, res.output
    assert (ran["namespace"], ran["node_name"], ran["points_topic"]) == ("/robot", "depth", "/lidar/points")
