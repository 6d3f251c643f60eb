"""The one interface a live ROS transport implements: it moves messages, nothing else.

A transport (DDS for ROS 2, TCPROS for ROS 1, ...) advertises and subscribes topics of ROS message
types named the ROS 2 way (``sensor_msgs/msg/Image``). Messages are ``rosbags`` message objects of
the transport's typestore (the same objects the bag writer writes): a transport serialises them in
its own wire format (CDR for ROS 2, ROS 1 serialisation for ROS 1) and deserialises what it receives.
The node builds each outgoing message once per frame and hands it to every publisher.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

__all__ = [
    "LATCHED_QOS",
    "OUTPUT_QOS",
    "SENSOR_QOS",
    "TF_QOS",
    "TF_STATIC_QOS",
    "Publisher",
    "QoS",
    "Transport",
]


@dataclass(frozen=True)
class QoS:
    """The part of a ROS 2 QoS profile the node sets: reliability, keep-last depth and durability (``durable``:
    transient local, a late subscriber gets the last ``depth`` messages, as ``/tf_static`` is published)."""

    reliable: bool
    depth: int
    durable: bool = False


#: What ROS 2 camera and LiDAR drivers publish with (rclcpp's sensor-data profile): best effort, keep-last 5.
SENSOR_QOS = QoS(reliable=False, depth=5)
#: What depth nodes publish with: reliable, keep-last 1 (a late subscriber gets only the newest frame).
OUTPUT_QOS = QoS(reliable=True, depth=1)
#: A latched output (``--latch-camera-info``): reliable, transient local, keep-last 1 (a late subscriber gets the
#: last message at once).
LATCHED_QOS = QoS(reliable=True, depth=1, durable=True)
#: What ``/tf`` is subscribed with (tf2's listener profile: reliable, volatile, keep-last 100).
TF_QOS = QoS(reliable=True, depth=100)
#: What ``/tf_static`` is subscribed with (tf2's static profile: reliable, transient local).
TF_STATIC_QOS = QoS(reliable=True, depth=100, durable=True)


class Publisher(Protocol):
    """One advertised topic."""

    def publish(self, message: object) -> None:
        """Send one message (a ``rosbags`` message object of the advertised type); never blocks for long."""


class Transport(Protocol):
    """Moves messages between the node and its peers.

    ``subscribe`` calls ``callback`` from the transport's own thread with each deserialised message; a
    message that cannot be deserialised is one logged line naming the topic, never an exception in the
    caller. ``close`` ends every thread and socket the transport started, within a bounded time.
    """

    name: str

    @property
    def typestore(self) -> object:
        """The ``rosbags`` type store its messages belong to (ROS 2 Humble's for DDS, ROS 1 Noetic's for TCPROS):
        the node builds its messages in it, never converting them on each publish."""

    def advertise(self, topic: str, msgtype: str, qos: QoS) -> Publisher:
        """Announce ``topic`` (absolute ROS name, e.g. ``/semattnet/depth_image``) of ``msgtype``."""

    def subscribe(self, topic: str, msgtype: str, qos: QoS, callback: Callable[[object], None]) -> None:
        """Receive ``topic`` of ``msgtype``; ``callback(message)`` for each message."""

    def close(self) -> None:
        """Stop receiving and sending; release every resource."""
