"""Per-topic QoS overrides, named as ``rclcpp`` names them, and the node's QoS by topic role.

ROS 2 nodes that allow it take ``qos_overrides.TOPIC.ENTITY.POLICY`` parameters (``rclcpp``'s
``QosOverridingOptions``): TOPIC the fully resolved topic name (after remapping), ENTITY ``publisher`` or
``subscription``, POLICY one of ``reliability`` (``reliable``, ``best_effort``), ``durability`` (``volatile``,
``transient_local``), ``history`` (``keep_last``) and ``depth`` (a positive count). In a parameter file they nest::

    /**:
      ros__parameters:
        qos_overrides:
          /semattnet/output/point_cloud:
            publisher:
              reliability: best_effort

On the command line ``--qos TOPIC:POLICY=VALUE[,POLICY=VALUE...]`` says the same (TOPIC any name the node
resolves, ``~/output/point_cloud`` or absolute; its entity is the node's one on that topic). The defaults:
:data:`~.transport.SENSOR_QOS` for the inputs, :data:`~.transport.OUTPUT_QOS` for the outputs (``camera_info``
latched with ``--latch-camera-info``), tf2's profiles for ``/tf`` and ``/tf_static``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from semattnet._errors import InputError
from semattnet.robotics.frame import ROS_TYPES

from .names import resolve_name
from .transport import LATCHED_QOS, OUTPUT_QOS, SENSOR_QOS, TF_QOS, TF_STATIC_QOS, QoS

__all__ = [
    "QOS_PREFIX",
    "ROS1_NO_QOS",
    "QosOverride",
    "default_qos",
    "node_qos",
    "parse_qos_option",
    "qos_override_param",
]

#: The parameter names' prefix (``rclcpp``'s).
QOS_PREFIX = "qos_overrides."
#: What ``semattnet ros1`` says of a QoS override.
ROS1_NO_QOS = (
    "ROS 1 has no QoS (TCPROS is TCP: a subscriber gets every message it keeps up with; --latch-camera-info "
    "latches camera_info); QoS overrides are semattnet ros2's"
)
#: The values each policy takes (``depth``: a positive integer).
QOS_CHOICES = {
    "reliability": ("reliable", "best_effort"),
    "durability": ("volatile", "transient_local"),
    "history": ("keep_last",),
    "depth": (),
}
#: The DDS entity the node has on a topic, by its kind (``rclcpp``'s words).
QOS_ENTITIES = ("publisher", "subscription")


@dataclass(frozen=True)
class QosOverride:
    """One policy of one topic: ``topic`` as given (resolved by :func:`node_qos`), ``entity`` (None: the node's
    one on that topic), the checked ``value``, and ``where`` it was given (for a one-line error)."""

    topic: str
    policy: str
    value: str | int
    where: str
    entity: str | None = None


def _checked(policy: str, value: object, where: str) -> str | int:
    """``value`` of ``policy`` as the node takes it; a one-line error naming ``where`` else."""
    if policy not in QOS_CHOICES:
        raise InputError(f"{where}: {policy!r} is not a QoS policy this node takes ({', '.join(QOS_CHOICES)})")
    if policy == "depth":
        text = str(value).strip()
        if isinstance(value, bool) or not text.isdigit() or int(text) < 1:
            raise InputError(f"{where}: depth {value!r}: expected a positive number of messages")
        return int(text)
    if value == "keep_all" and policy == "history":
        raise InputError(f"{where}: history keep_all: not taken (the node keeps the last DEPTH messages; set depth)")
    if value not in QOS_CHOICES[policy]:
        raise InputError(f"{where}: {policy} {value!r}: expected one of {', '.join(QOS_CHOICES[policy])}")
    return str(value)


def qos_override_param(key: str, value: object, where: str) -> QosOverride:
    """A ``qos_overrides.TOPIC.ENTITY.POLICY`` parameter (module doc).

    >>> qos_override_param("qos_overrides./cam/image.subscription.depth", 2, "-p").value
    2
    """
    parts = key.removeprefix(QOS_PREFIX).split(".")
    if len(parts) != 3 or parts[1] not in QOS_ENTITIES or not parts[0]:
        raise InputError(f"{where}: expected qos_overrides.TOPIC.publisher|subscription.POLICY")
    topic, entity, policy = parts
    return QosOverride(topic, policy, _checked(policy, value, where), where, entity)


def parse_qos_option(text: str) -> tuple[QosOverride, ...]:
    """``--qos TOPIC:POLICY=VALUE[,POLICY=VALUE...]`` (module doc).

    >>> tuple((o.policy, o.value) for o in parse_qos_option("~/output/point_cloud:reliability=best_effort,depth=2"))
    (('reliability', 'best_effort'), ('depth', 2))
    """
    where = f"--qos {text!r}"
    topic, colon, rest = text.rpartition(":")
    pairs = [p.partition("=") for p in rest.split(",")]
    if not colon or not topic.strip() or any(not sep or not k.strip() for k, sep, _ in pairs):
        raise InputError(f"{where}: expected TOPIC:POLICY=VALUE[,POLICY=VALUE...] (e.g. ~/output/point_cloud:depth=2)")
    topic = topic.strip()
    return tuple(QosOverride(topic, k.strip(), _checked(k.strip(), v.strip(), where), where) for k, _, v in pairs)


def default_qos(latch_camera_info: bool = False) -> dict[str, QoS]:
    """The node's QoS by topic role (:meth:`~.node.NodeTopics.resolved`'s keys) before any override."""
    qos = {"image": SENSOR_QOS, "camera_info": SENSOR_QOS, "scan": SENSOR_QOS, "tf": TF_QOS, "tf_static": TF_STATIC_QOS}
    qos |= {f"out:{role}": OUTPUT_QOS for role in ROS_TYPES}
    if latch_camera_info:
        qos["out:camera_info"] = LATCHED_QOS
    return qos


def _applied(qos: QoS, override: QosOverride) -> QoS:
    if override.policy == "reliability":
        return dataclasses.replace(qos, reliable=override.value == "reliable")
    if override.policy == "durability":
        return dataclasses.replace(qos, durable=override.value == "transient_local")
    if override.policy == "depth":
        return dataclasses.replace(qos, depth=int(override.value))
    return qos  # history keep_last: what the node keeps anyway


def node_qos(
    overrides: Iterable[QosOverride],
    names: Mapping[str, str],
    namespace: str = "",
    node: str = "semattnet",
    latch_camera_info: bool = False,
) -> dict[str, QoS]:
    """The QoS of each of the node's topics by role: :func:`default_qos` with ``overrides`` applied in order (a
    later one wins). ``names``: the node's resolved topics by role (:meth:`~.node.NodeTopics.resolved`).

    Raises:
        InputError: an override of a topic the node neither publishes nor subscribes, or of the wrong entity (a
            ``publisher`` override of an input); one line naming where it was given.
    """
    roles = {name: role for role, name in names.items()}
    qos = default_qos(latch_camera_info)
    for o in overrides:
        topic = resolve_name(o.topic, namespace, node, o.where)
        role = roles.get(topic)
        if role is None:
            have = ", ".join(sorted(roles))
            raise InputError(f"{o.where}: {topic} is not one of the node's topics ({have})")
        entity = "publisher" if role.startswith("out:") else "subscription"
        if o.entity not in (None, entity):
            raise InputError(f"{o.where}: the node has a {entity} on {topic}, not a {o.entity}")
        qos[role] = _applied(qos[role], o)
    return qos
