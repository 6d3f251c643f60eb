"""The node's health on ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``), as ROS drivers report theirs.

Every report interval (and once on stop) the node publishes one ``DiagnosticStatus`` named
``semattnet: /NS/NODE`` (hardware id: the same name), whose level is

- ERROR: an expected input (image, scan, camera_info without a rig) never came or has not come for
  :data:`MISSING_PERIODS` report intervals, or frames failed in the interval and none completed;
- WARN: frames failed, pairs were dropped (stale) or images went unpaired in the interval, or an expected
  input did not come in it;
- OK: otherwise; STALE on the last status (the node stopped).

Its values (``KeyValue``, strings) are :data:`KEYS` (``since_*_s``: seconds since the report at which that
input's count had last grown, so to the report interval; ``never`` before the first) and, per stage timed in
the interval, ``latency_STAGE_mean_ms`` / ``latency_STAGE_max_ms``; ``socket_drops``: the datagrams the kernel
dropped at the node's UDP sockets (``unknown`` off Linux or over TCPROS). What it reads of the node is one snapshot,
:class:`NodeHealth`, made by one adapter, :func:`node_health`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from semattnet.robotics.bags.encode import header

from .transport import QoS, Transport

if TYPE_CHECKING:
    from semattnet.geometry import RigCalibration
    from semattnet.robotics.bags.deps import Typestore

    from .status import NodeStatus
    from .transport import Publisher

__all__ = [
    "DIAGNOSTICS_QOS",
    "DIAGNOSTICS_TOPIC",
    "KEYS",
    "MISSING_PERIODS",
    "Diagnostics",
    "HealthSource",
    "NodeHealth",
    "node_health",
]

log = logging.getLogger("semattnet.ros")

#: The topic (absolute, never remapped by the node's namespace, as ``diagnostic_updater`` publishes it).
DIAGNOSTICS_TOPIC = "/diagnostics"
#: ``diagnostic_updater``'s QoS: reliable, volatile, keep-last 10 (rclcpp's default).
DIAGNOSTICS_QOS = QoS(reliable=True, depth=10)
#: Report intervals without an expected input before the status is ERROR.
MISSING_PERIODS = 3
#: The levels of ``diagnostic_msgs/DiagnosticStatus``.
OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: The keys of every status, in order (the stages' latency keys follow them).
KEYS = (
    "rate_hz",
    "frames_completed",
    "frames_failed",
    "frames_stale",
    "images_unpaired",
    "bad_messages",
    "socket_drops",
    "received_image",
    "received_scan",
    "received_camera_info",
    "since_image_s",
    "since_scan_s",
    "since_camera_info_s",
)
_ROLES = ("image", "scan", "camera_info")


@dataclass(frozen=True)
class NodeHealth:
    """What ``/diagnostics`` reads of the node: totals since the start, the stage times of the interval
    (stage -> (mean ms, max ms)), and the inputs it needs (``image``, ``scan``, ``camera_info``)."""

    completed: int
    failed: int
    stale: int
    unpaired: int
    bad: int
    received: Mapping[str, int]
    stages_ms: Mapping[str, tuple[float, float]]
    expected: tuple[str, ...] = ("image", "scan")
    socket_drops: int | None = None  # datagrams the kernel dropped at the node's UDP sockets (None: not known)


class HealthSource(Protocol):
    """What :func:`node_health` reads of the node (:class:`~.node.DepthNode`): its snapshot and its rig."""

    rig: RigCalibration | None

    def status(self) -> NodeStatus: ...


def node_health(node: HealthSource) -> NodeHealth:
    """The one adapter from the node's snapshot (:meth:`~.node.DepthNode.status`: its counts and the stage tally of
    the current interval, read before the report line starts a new one) to :class:`NodeHealth`."""
    s = node.status()
    stages = {k: (v[1] / v[0], v[2]) for k, v in s.tally.period.items() if v[0]}
    expected = ("image", "scan") if node.rig is not None else _ROLES
    received = {role: t.received for role, t in s.topics.items() if t.received}
    return NodeHealth(s.completed, s.failed, s.stale, s.lost, s.bad, received, stages, expected, s.socket_drops)


@dataclass
class _Seen:
    """When the node started, the previous status (when, its totals) and when each input's count was first seen
    grown (monotonic seconds: to the report interval)."""

    started: float
    at: float
    health: NodeHealth | None = None
    last: dict[str, float] = field(default_factory=dict)


class Diagnostics:
    """Publishes the node's :class:`NodeHealth` on ``/diagnostics`` (module doc); ``name`` is the node's fully
    qualified name, ``period_s`` its report interval."""

    def __init__(
        self, transport: Transport, name: str, period_s: float, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.transport, self.name, self.period_s, self.clock = transport, name, period_s, clock
        self.publisher: Publisher | None = None
        self.seen = _Seen(clock(), clock())

    def advertise(self) -> None:
        """Advertise ``/diagnostics``."""
        self.publisher = self.transport.advertise(
            DIAGNOSTICS_TOPIC, "diagnostic_msgs/msg/DiagnosticArray", DIAGNOSTICS_QOS
        )

    def publish(self, health: NodeHealth, final: bool = False) -> object:
        """Publish one status of ``health`` (``final``: STALE, the node stopped); the message."""
        now = self.clock()
        level, text, values = self.status(health, now)
        if final:
            level, text = STALE, f"stopped ({text})"
        ts: Typestore = self.transport.typestore  # type: ignore[assignment]
        kv, st = ts.types["diagnostic_msgs/msg/KeyValue"], ts.types["diagnostic_msgs/msg/DiagnosticStatus"]
        status = st(
            level=level,
            name=f"semattnet: {self.name}",
            message=text,
            hardware_id=self.name,
            values=[kv(key=k, value=v) for k, v in values.items()],
        )
        message = ts.types["diagnostic_msgs/msg/DiagnosticArray"](
            header=header(ts, time.time_ns(), ""), status=[status]
        )
        if self.publisher is not None:
            try:
                self.publisher.publish(message)
            except Exception as exc:  # the node's health report never stops the node: one line
                log.warning("/diagnostics: not published (%s: %s)", type(exc).__name__, exc)
        return message

    def status(self, health: NodeHealth, now: float) -> tuple[int, str, dict[str, str]]:
        """(level, message, values) of ``health`` at ``now``, against the previous status (module doc)."""
        seen, before = self.seen, self.seen.health
        span = max(now - seen.at, 1e-9)
        for role in _ROLES:
            if health.received.get(role, 0) > (before.received.get(role, 0) if before else 0):
                seen.last[role] = now
        done = health.completed - (before.completed if before else 0)
        failed = health.failed - (before.failed if before else 0)
        dropped = health.stale + health.unpaired - ((before.stale + before.unpaired) if before else 0)
        since = {role: now - seen.last[role] for role in _ROLES if role in seen.last}
        missing = [r for r in health.expected if since.get(r, now - seen.started) >= MISSING_PERIODS * self.period_s]
        quiet = [r for r in health.expected if since.get(r, span) >= min(span, self.period_s) * 0.999]
        if missing:
            level, text = ERROR, f"no {', '.join(missing)} for {MISSING_PERIODS} report intervals"
        elif failed and not done:
            level, text = ERROR, f"{failed} frame(s) failed, none completed"
        elif failed or dropped or quiet:
            parts = [f"{failed} frame(s) failed"] * bool(failed) + [f"{dropped} pair(s) dropped"] * bool(dropped)
            level, text = WARN, ", ".join(parts + [f"no {', '.join(quiet)} in the interval"] * bool(quiet))
        else:
            level, text = OK, f"{done} frame(s) completed"
        values = self._values(health, done / span, since)
        seen.at, seen.health = now, health
        return level, text, values

    @staticmethod
    def _values(health: NodeHealth, rate: float, since: Mapping[str, float]) -> dict[str, str]:
        counts = (health.completed, health.failed, health.stale, health.unpaired, health.bad)
        values = dict(zip(KEYS[1:6], map(str, counts), strict=True))
        drops = "unknown" if health.socket_drops is None else str(health.socket_drops)
        values = {"rate_hz": f"{rate:.2f}", **values, "socket_drops": drops}
        values |= {f"received_{r}": str(health.received.get(r, 0)) for r in _ROLES}
        values |= {f"since_{r}_s": f"{since[r]:.2f}" if r in since else "never" for r in _ROLES}
        for stage, (mean, worst) in health.stages_ms.items():
            values[f"latency_{stage}_mean_ms"], values[f"latency_{stage}_max_ms"] = f"{mean:.1f}", f"{worst:.1f}"
        return values
