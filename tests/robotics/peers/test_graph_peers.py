"""The node in the ROS 2 graph, read by a program that is not ours: a Cyclone DDS C reader (types from
rmw_dds_common's and diagnostic_msgs' Humble .msg definitions, ``ros_graph.idl``) decodes ``ros_discovery_info``
as rmw does (the node's namespace, name and endpoint GIDs), ``/diagnostics`` with the documented keys and
``/rosout`` (rcl_interfaces' Log, the node's logger name and report lines), and finds
the same endpoints' GUIDs independently in the DDS built-in topics. ``pytest -m ros_peers``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from semattnet.robotics.ros.diagnostics import KEYS

from ._netns import run_isolated

pytestmark = pytest.mark.ros_peers


def test_cyclone_c_reads_the_node_in_the_graph_and_its_diagnostics(peers: dict[str, Path], tmp_path: Path) -> None:
    from semattnet.robotics.ros.dds import loopback_config

    out = tmp_path / "run"
    node = [sys.executable, "-m", "semattnet", "ros2", "--loopback", "--method", "classical", "--report-every", "0.5"]
    node += ["--ros-args", "-r", "__ns:=/robot", "-r", "__node:=depth", "-r", "~/input/image:=/camera/image_raw"]
    reader = [str(peers["graph"]), "depth", "60"]
    status = run_isolated(
        out,
        [
            {"name": "node", "argv": node},
            {"name": "graph", "argv": reader, "env": {"CYCLONEDDS_URI": loopback_config(0)}, "wait": True, "delay": 1},
        ],
        70,
    )
    lines = (out / "graph.out").read_text().splitlines()
    assert status["graph"] == 0 and status["node"] == 0, (status, lines[-20:], (out / "node.err").read_text()[-2000:])
    *_, announced = [line.split() for line in lines if line.startswith("node ") and " depth R" in line]
    participant, namespace, name = announced[1:4]
    at = announced.index("W")
    readers, writers = set(announced[5:at]), set(announced[at + 1 :])
    assert (namespace, name) == ("/robot", "depth") and participant.endswith("0" * 16)
    guid = participant[:32]

    def endpoints(kind: str) -> dict[str, str]:
        rows = [line.split() for line in lines if line.startswith(kind + " ")]
        return {r[1] + "0" * 16: r[3] for r in rows if r[2] == guid and r[3] != "ros_discovery_info"}

    pubs, subs = endpoints("pub"), endpoints("sub")
    assert writers == set(pubs) and readers == set(subs), (writers, pubs, readers, subs)
    assert "rt/camera/image_raw" in subs.values() and "rt/robot/depth/output/depth_image" in pubs.values()
    assert "rt/diagnostics" in pubs.values()
    assert f"participant {guid} enclave=/;" in lines
    diag = next(line for line in lines if line.startswith("diag "))
    level, rest = diag.split(" ", 2)[1:]
    fields = rest.split("|")
    assert fields[:2] == ["semattnet: /robot/depth", "/robot/depth"] and level in ("1", "2")
    assert set(KEYS) <= {f.split("=", 1)[0] for f in fields[2:]}
    assert "rt/rosout" in pubs.values()
    logs = [line.split(" ", 2)[1:] for line in lines if line.startswith("log ")]
    level, text = logs[0]
    name, function, message = text.split("|", 2)
    assert (level, name, function) == ("20", "robot.depth", "report") and message, logs
