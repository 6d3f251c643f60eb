"""Foreign DDS peers of the ROS 2 node, built once per session into a temporary folder (never committed):
a Fast DDS C++ camera publisher and subscriber (fastddsgen types) and a Cyclone DDS C subscriber (idlc types),
all of ``sensor_msgs.idl``, and a Cyclone DDS C reader of the ROS 2 graph (``ros_graph.idl``). Every run happens
in its own loopback-only network namespace (:func:`run_isolated`). Missing tools (``bash
scripts/setup-ros-peers.sh`` installs them) skip the tests with the reason (fail them with
``SEMATTNET_REQUIRE_ROS_PEERS=1``, as ``make test-ros-peers`` sets)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from ._netns import unshare_prefix

HERE = Path(__file__).parent
TOOLS = ("fastddsgen", "idlc", "cmake", "c++", "cc", "unshare", "ip", "java")
HEADERS = ("/usr/include/fastdds/dds/domain/DomainParticipant.hpp", "/usr/include/dds/dds.h")


def _missing() -> str | None:
    """Why the peers cannot run here, or None."""
    pytest.importorskip("cyclonedds", reason="the node's DDS needs cyclonedds: pip install 'semattnet[ros2]'")
    lacking = [t for t in TOOLS if shutil.which(t) is None] + [h for h in HEADERS if not Path(h).is_file()]
    if lacking:
        return f"no {', '.join(lacking)}: run `bash scripts/setup-ros-peers.sh` (Debian: Fast DDS, Cyclone DDS C)"
    if unshare_prefix() is None:
        return "cannot make a network namespace (unshare --net, as root or in a user namespace)"
    return None


def _run(argv: list[str], cwd: Path, what: str) -> None:
    done = subprocess.run(argv, cwd=cwd, capture_output=True, timeout=300)
    if done.returncode != 0:
        raise RuntimeError(
            f"{what} failed ({done.returncode}): {done.stdout.decode()[-2000:]}{done.stderr.decode()[-2000:]}"
        )


@pytest.fixture(scope="session")
def peers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """{"fastdds": the Fast DDS peer, "cyclone": the Cyclone C subscriber, "graph": the Cyclone C reader of
    ros_discovery_info, /diagnostics and the built-in topics}, built from the IDL files."""
    why = _missing()
    if why is not None:
        if os.environ.get("SEMATTNET_REQUIRE_ROS_PEERS"):  # CI: a missing peer is a failure, not a skip
            pytest.fail(why)
        pytest.skip(why)
    root = tmp_path_factory.mktemp("ros_peers")
    fast, cyc = root / "fastdds", root / "cyclone"
    fast.mkdir()
    cyc.mkdir()
    _run(["fastddsgen", "-replace", "-d", str(fast), str(HERE / "sensor_msgs.idl")], root, "fastddsgen")
    _run(
        [
            "cmake",
            "-S",
            str(HERE),
            "-B",
            str(fast / "build"),
            "-DCMAKE_BUILD_TYPE=Release",
            f"-DPEER_SOURCE={HERE / 'fastdds_peer.cpp'}",
            f"-DGENERATED={fast}",
        ],
        root,
        "cmake",
    )
    _run(["cmake", "--build", str(fast / "build"), "-j2"], root, "building the Fast DDS peer")
    _run(["idlc", str(HERE / "sensor_msgs.idl")], cyc, "idlc")
    _run(
        [
            "cc",
            "-O1",
            f"-I{cyc}",
            "-o",
            str(cyc / "cyclone_sub"),
            str(HERE / "cyclone_sub.c"),
            str(cyc / "sensor_msgs.c"),
            "-lddsc",
        ],
        cyc,
        "building the Cyclone subscriber",
    )
    graph = root / "graph"
    graph.mkdir()
    _run(["idlc", str(HERE / "ros_graph.idl")], graph, "idlc")
    argv = ["cc", "-O1", f"-I{graph}", "-o", str(graph / "cyclone_graph"), str(HERE / "cyclone_graph.c")]
    _run([*argv, str(graph / "ros_graph.c"), "-lddsc"], graph, "building the Cyclone graph reader")
    return {
        "fastdds": fast / "build" / "fastdds_peer",
        "cyclone": cyc / "cyclone_sub",
        "graph": graph / "cyclone_graph",
    }
