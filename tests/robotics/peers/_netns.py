"""Running processes together in a loopback-only network namespace, for the foreign-peer tests."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).parent


def run_isolated(out: Path, procs: list[dict[str, object]], timeout: float) -> dict[str, int | None]:
    """Run ``procs`` (:mod:`scenario`'s spec) together in a new loopback-only network namespace; their exit
    statuses (None: still running at ``timeout``, then ended)."""
    out.mkdir(parents=True, exist_ok=True)
    spec = out / "spec.json"
    spec.write_text(json.dumps({"out": str(out), "timeout": timeout, "procs": procs}))
    inner = 'ip link set lo up && exec "$0" "$@"'
    argv = ["unshare", "--net", "--", "sh", "-c", inner, sys.executable, str(HERE / "scenario.py"), str(spec)]
    subprocess.run(argv, check=True, timeout=timeout + 40, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    status: dict[str, int | None] = json.loads((out / "status.json").read_text())
    return status
