"""``semattnet ros1`` ends when asked, whatever its master does: a Ctrl-C at any moment of its start is one line
(no traceback); SIGINT ends it within 2 s while the master drips one byte every 2 s at unregister; the XML-RPC
``shutdown`` call (roscore's on a node-name clash) ends it with one line naming the caller's reason, exit status 0;
a master dripping at start is refused in one line, not waited on."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import xmlrpc.client
from pathlib import Path

import pytest

from ._hostile_ros1 import ThreadedMaster, threaded_master

pytest.importorskip("rosbags")

REPO = Path(__file__).resolve().parents[3]
#: A hang guard (not a measurement): starting the command imports torch, seconds on a busy CI machine.
GUARD_S = 120.0
UNREGISTER = frozenset({"unregisterPublisher", "unregisterSubscriber"})


def _node(master: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")}
    argv = [sys.executable, "-m", "semattnet", "ros1", "--master", master, "--method", "classical"]
    return subprocess.Popen(argv, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _ended(node: subprocess.Popen[str]) -> tuple[float, str]:
    """Seconds from now until ``node`` ends, and its output (killed past the guard: the test fails)."""
    start = time.monotonic()
    try:
        out, _ = node.communicate(timeout=GUARD_S)
    except subprocess.TimeoutExpired:
        node.kill()
        out, _ = node.communicate()
        pytest.fail(f"still running {GUARD_S} s later: {out[-2000:]}")
    return time.monotonic() - start, out


def _registered(master: ThreadedMaster, node: subprocess.Popen[str]) -> None:
    """Wait until the node has registered its topics (5 outputs and inputs at least)."""
    deadline = time.monotonic() + GUARD_S
    while len(master.apis) < 5 and node.poll() is None:
        assert time.monotonic() < deadline, "the node never registered"
        time.sleep(0.05)
    time.sleep(0.5)


@pytest.mark.slow  # about 2 minutes: three whole starts of the node, one after the other
def test_ctrl_c_at_any_moment_of_the_start_is_one_line_without_a_traceback() -> None:
    """SIGINT while Python imports torch, loads the model, registers, or runs: 'Aborted!' (status 1) before the
    node runs, its summary (status 0) after; never a traceback."""
    results = []
    with threaded_master() as master:
        for moment in (1.0, 2.5, 6.0):  # one at a time: each start as fast as it is alone
            node = _node(master.uri)
            time.sleep(moment)
            node.send_signal(signal.SIGINT)
            out = _ended(node)[1]
            results.append((moment, node.returncode, out))
    for moment, code, out in results:
        assert "Traceback" not in out and "KeyboardInterrupt" not in out, (moment, out[-3000:])
        if code == 1:
            assert out.strip() == "Aborted!", (moment, out[-3000:])
        else:
            assert code == 0 and "ros node stopped:" in out, (moment, code, out[-3000:])


def test_sigint_ends_the_node_within_2_s_while_the_master_drips_at_unregister() -> None:
    with threaded_master(UNREGISTER, period=2.0) as master:
        node = _node(master.uri)
        _registered(master, node)
        node.send_signal(signal.SIGINT)
        took, out = _ended(node)
    assert node.returncode == 0, out[-3000:]
    assert master.dripped and "no answer to unregister within 0.5 s" in out, out[-3000:]
    assert took < 2.0 + 1.0, (took, out[-3000:])  # the promise (2 s) and a margin for a busy machine; was 20 s


def test_the_shutdown_call_ends_the_node_in_one_line_naming_its_reason() -> None:
    with threaded_master(UNREGISTER, period=2.0) as master:
        node = _node(master.uri)
        _registered(master, node)
        reply = xmlrpc.client.ServerProxy(master.apis[0]).shutdown("/roscore", "new node registered with same name")
        took, out = _ended(node)
    assert reply[0] == 1 and node.returncode == 0, out[-3000:]
    lines = [line for line in out.splitlines() if "shut down" in line]
    assert lines == ["ROS 1: '/roscore' asked this node to shut down ('new node registered with same name'); stopping"]
    assert "ros node stopped:" in out and "Traceback" not in out, out[-3000:]
    assert took < 2.0 + 1.0, (took, out[-3000:])


def test_a_master_dripping_at_start_is_refused_in_one_line() -> None:
    with threaded_master(frozenset({"getUri"}), period=2.0) as master:
        _, out = _ended(_node(master.uri))
    errors = [line for line in out.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1, out[-3000:]
    assert errors[0].startswith(f"Error: ROS master {master.uri} getUri: no whole reply within 5 s"), out[-3000:]
    assert "Traceback" not in out
