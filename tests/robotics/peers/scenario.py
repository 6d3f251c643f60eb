"""Run a set of processes together (inside a loopback-only network namespace) and end them by PID.

``python scenario.py SPEC.json``: SPEC is ``{"out": DIR, "timeout": S, "procs": [{"name", "argv", "env", "wait",
"delay"}]}``. Every process starts (after ``delay`` seconds) with its stdout and stderr in ``DIR/NAME.out`` /
``DIR/NAME.err``; the ``wait`` ones are waited for (at most ``timeout`` seconds in all), then the others get
SIGTERM, and SIGKILL 10 s later. ``DIR/status.json``: each process's exit status (null: killed at the timeout).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def main(spec_path: str) -> int:
    spec = json.loads(Path(spec_path).read_text())
    out, deadline = Path(spec["out"]), time.monotonic() + float(spec["timeout"])
    procs: dict[str, subprocess.Popen[bytes]] = {}
    for p in spec["procs"]:
        time.sleep(float(p.get("delay", 0)))
        env = {**os.environ, **p.get("env", {})}
        with (out / f"{p['name']}.out").open("wb") as so, (out / f"{p['name']}.err").open("wb") as se:
            procs[p["name"]] = subprocess.Popen(p["argv"], stdout=so, stderr=se, env=env)
    status: dict[str, int | None] = {}
    for p in spec["procs"]:
        if p.get("wait"):
            try:
                status[p["name"]] = procs[p["name"]].wait(max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                status[p["name"]] = None
    for proc in procs.values():
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGTERM)
    for name, proc in procs.items():
        try:
            code = proc.wait(10)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGKILL)
            code = proc.wait()
        status.setdefault(name, code)
    (out / "status.json").write_text(json.dumps(status))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
