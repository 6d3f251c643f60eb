"""Running processes together in a loopback-only network namespace, for the foreign-peer tests."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).parent
#: How to enter a new network namespace: as root, or (without root) in a user namespace mapping us to root.
UNSHARE = (["unshare", "--net"], ["unshare", "--user", "--map-root-user", "--net"])


def unshare_prefix() -> list[str] | None:
    """The first of :data:`UNSHARE` that works here (None: none does)."""
    for prefix in UNSHARE:
        probe = subprocess.run([*prefix, "true"], capture_output=True, timeout=10)
        if probe.returncode == 0:
            return prefix
    return None


def run_isolated(out: Path, procs: list[dict[str, object]], timeout: float) -> dict[str, int | None]:
    """Run ``procs`` (:mod:`scenario`'s spec) together in a new loopback-only network namespace; their exit
    statuses (None: still running at ``timeout``, then ended)."""
    out.mkdir(parents=True, exist_ok=True)
    spec = out / "spec.json"
    spec.write_text(json.dumps({"out": str(out), "timeout": timeout, "procs": procs}))
    inner = 'ip link set lo up && exec "$0" "$@"'
    prefix = unshare_prefix()
    assert prefix is not None  # the peers fixture skipped otherwise
    argv = [*prefix, "--", "sh", "-c", inner, sys.executable, str(HERE / "scenario.py"), str(spec)]
    subprocess.run(argv, check=True, timeout=timeout + 40, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    status: dict[str, int | None] = json.loads((out / "status.json").read_text())
    return status
