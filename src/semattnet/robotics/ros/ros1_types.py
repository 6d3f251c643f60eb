"""ROS 1 message types for the TCPROS transport: names (``sensor_msgs/msg/Image`` <-> ``sensor_msgs/Image``)
and rosbags objects of another type store (ROS 2) converted to the ROS 1 store's (:func:`adopt_message`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Protocol

from semattnet._errors import InputError

__all__ = ["Ros1Store", "adopt_message", "ros1_type_name", "store_type_name"]

_MISSING = object()


class Ros1Store(Protocol):
    """What the transport uses of rosbags' ROS 1 type store."""

    @property
    def types(self) -> Mapping[str, type]: ...

    def serialize_ros1(self, message: object, typename: str) -> memoryview: ...

    def deserialize_ros1(self, rawdata: bytes, typename: str) -> object: ...

    def generate_msgdef(self, typename: str) -> tuple[str, str]: ...


def ros1_type_name(msgtype: str) -> str:
    """The ROS 1 name of a type: ``sensor_msgs/msg/Image`` -> ``sensor_msgs/Image``."""
    package, sep, name = msgtype.partition("/msg/")
    return f"{package}/{name}" if sep else msgtype


def store_type_name(msgtype: str) -> str:
    """The type store's name of a type: ``sensor_msgs/Image`` -> ``sensor_msgs/msg/Image`` (unchanged if so already)."""
    if "/msg/" in msgtype:
        return msgtype
    package, sep, name = msgtype.partition("/")
    return f"{package}/msg/{name}" if sep and name else msgtype


def adopt_message(store: Ros1Store, message: object) -> object:
    """``message`` as an object of ``store``: objects of another rosbags store are converted by field name.

    A ROS 2 object converts: ``CameraInfo``'s ``d``/``k``/``r``/``p`` fill ROS 1's ``D``/``K``/``R``/``P``,
    and a field ROS 2 lacks (``Header.seq``) is 0. Arrays, strings and numbers pass through.
    """
    if isinstance(message, list):
        return [adopt_message(store, item) for item in message]
    name = getattr(type(message), "__msgtype__", None)
    if not isinstance(name, str):
        return message
    cls = store.types.get(name)
    if cls is None:
        raise InputError(f"message type {name}: not a ROS 1 Noetic type")
    if type(message) is cls:
        return message
    values = {}
    for field in dataclasses.fields(cls):
        if not field.name.startswith("__"):
            value = getattr(message, field.name, getattr(message, field.name.lower(), _MISSING))
            values[field.name] = 0 if value is _MISSING else adopt_message(store, value)
    return cls(**values)
