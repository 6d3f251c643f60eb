"""The node's outputs: :class:`RosPublishSink` publishes each completed frame's messages under ``~/output``, and
what chooses them (``--publish``'s roles, the cloud's stride, whether the completer gives an uncertainty).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, cast

from semattnet._errors import InputError
from semattnet.inference.sinks import Prediction, RunSink
from semattnet.robotics.frame import ROS_TYPES, TOPICS, RobotFrame

from .transport import LATCHED_QOS, OUTPUT_QOS, Publisher, QoS, Transport

if TYPE_CHECKING:
    from semattnet.inference.uncertainty import UncertaintyLimit
    from semattnet.robotics.bags.deps import Typestore

__all__ = ["CLOUD_STRIDE", "OUTPUT_ROLES", "RosPublishSink", "gives_uncertainty", "output_roles"]

#: The published cloud's default stride: every 4th pixel both ways (29k of 465k points at 375x1242, what a
#: costmap needs).
CLOUD_STRIDE = 4


#: The outputs ``--publish`` chooses among, by their topic names under ``~/output``, and their roles.
OUTPUT_ROLES = {TOPICS[role]: role for role in ROS_TYPES}


def output_roles(names: Collection[str] | None) -> frozenset[str]:
    """The roles of output topic names (``depth_image``, ``point_cloud``, ``uncertainty``, ``camera_info``;
    None: all of them).

    Raises:
        InputError: a name that is not one of them (one line naming it and the choices).
    """
    if names is None:
        return frozenset(ROS_TYPES)
    bad = [n for n in names if n not in OUTPUT_ROLES]
    if bad or not names:
        have = ", ".join(OUTPUT_ROLES)
        raise InputError(f"--publish {','.join(names)!r}: expected one or more of {have}, comma-separated")
    return frozenset(OUTPUT_ROLES[n] for n in names)


def gives_uncertainty(completer: object) -> bool | None:
    """Whether ``completer`` gives a per-pixel uncertainty: its ``gives_uncertainty`` (the classical baseline), a
    :class:`~semattnet.inference.DepthCompleter`'s ``compute_uncertainty``; None when it does not say."""
    for attr in ("gives_uncertainty", "compute_uncertainty"):
        value = getattr(completer, attr, None)
        if isinstance(value, bool):
            return value
    return None


class RosPublishSink(RunSink):
    """The node's topics as a run sink: each completed frame's messages (:class:`RobotFrame`, built once in the
    transport's type store) published under ``~/output``: the float depth (``predict --npy``'s, not the PNG's
    1/256 m steps), the cloud of every ``cloud_stride``-th pixel both ways leaving out pixels deeper than
    ``max_depth`` or above ``max_uncertainty``, the uncertainty, the CameraInfo (latched with ``latch_camera_info``);
    ``roles`` the ones published; ``qos`` the QoS of some of them by role, over the defaults (:mod:`.qos`).
    ``uncertainty``: whether the completer gives one (False: never advertised; None, not known: advertised with the
    first frame that has one)."""

    replays = False

    def __init__(
        self,
        transport: Transport,
        names: dict[str, str],
        max_depth: float | None = None,
        max_uncertainty: UncertaintyLimit | None = None,
        *,
        roles: frozenset[str] = frozenset(ROS_TYPES),
        cloud_stride: int = CLOUD_STRIDE,
        latch_camera_info: bool = False,
        uncertainty: bool | None = True,
        qos: Mapping[str, QoS] | None = None,
    ) -> None:
        if cloud_stride < 1:
            raise InputError(f"--cloud-stride: expected a positive number of pixels, got {cloud_stride}")
        self.transport, self.names = transport, names
        self.max_depth, self.max_uncertainty = max_depth, max_uncertainty
        self.roles = roles - ({"uncertainty"} if uncertainty is False else set())
        self.cloud_stride, self.uncertainty = cloud_stride, uncertainty
        self.qos = {role: OUTPUT_QOS for role in ROS_TYPES}
        if latch_camera_info:
            self.qos["camera_info"] = LATCHED_QOS
        self.qos.update(qos or {})
        self.publishers: dict[str, Publisher] = {}
        self.muted = False

    def mute(self) -> None:
        """Publish nothing more: the node stopped without waiting for the frame in hand, which is not sent if it
        ever finishes (the loop's ``close`` ends a spin only: a node spun again publishes again)."""
        self.muted = True

    def reads(self) -> frozenset[str] | None:
        return RobotFrame.reads("uncertainty" in self.roles, self.max_uncertainty)

    def advertise(self) -> None:
        """Advertise the output topics (before the inputs are subscribed); the uncertainty's only when the
        completer is known to give one."""
        for role in sorted(self.roles):
            if role != "uncertainty" or self.uncertainty:
                self._advertise(role)

    def _advertise(self, role: str) -> Publisher:
        topic = self.names[f"out:{role}"]
        pub = self.publishers[role] = self.transport.advertise(topic, ROS_TYPES[role], self.qos[role])
        return pub

    def write(self, stage: Path, pred: Prediction) -> None:
        if self.muted:
            return
        robot = RobotFrame.of(
            pred,
            uncertainty=pred.uncertainty is not None and "uncertainty" in self.roles,
            max_depth=self.max_depth,
            max_uncertainty=self.max_uncertainty,
            float_depth=True,
            cloud_stride=self.cloud_stride if "points" in self.roles else 0,
        )
        for role, msg in robot.messages(cast("Typestore", self.transport.typestore), self.roles).items():
            (self.publishers.get(role) or self._advertise(role)).publish(msg)
