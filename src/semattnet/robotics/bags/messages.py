"""The fields of the ROS messages semattnet reads, as protocols: what the decoders ask of the message objects
rosbags deserialises (ROS 1 and ROS 2 alike, module doc of :mod:`.decode`). Typing only: nothing here checks a
message at run time (the decoders refuse a bad one with a :class:`~semattnet.DataError` naming its topic)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

__all__ = [
    "CameraInfoMsg",
    "CompressedImageMsg",
    "HeaderMsg",
    "ImageMsg",
    "PointCloud2Msg",
    "PointFieldMsg",
    "TFMessageMsg",
    "TimeMsg",
]


class TimeMsg(Protocol):
    """``builtin_interfaces/Time`` (rosbags names ROS 1's ``secs``/``nsecs`` so too)."""

    @property
    def sec(self) -> int: ...
    @property
    def nanosec(self) -> int: ...


class HeaderMsg(Protocol):
    """``std_msgs/Header``."""

    @property
    def stamp(self) -> TimeMsg: ...
    @property
    def frame_id(self) -> str: ...


class _Stamped(Protocol):
    """A message with a ``header``."""

    @property
    def header(self) -> HeaderMsg: ...


class _Grid(_Stamped, Protocol):
    """A stamped message of ``height`` x ``width`` pixels or points."""

    @property
    def height(self) -> int: ...
    @property
    def width(self) -> int: ...


class ImageMsg(_Grid, Protocol):
    """``sensor_msgs/Image``: ``height`` rows of ``step`` bytes in ``data``."""

    @property
    def encoding(self) -> str: ...
    @property
    def is_bigendian(self) -> int: ...
    @property
    def step(self) -> int: ...
    @property
    def data(self) -> np.ndarray: ...


class CompressedImageMsg(_Stamped, Protocol):
    """``sensor_msgs/CompressedImage``: JPEG or PNG bytes."""

    @property
    def format(self) -> str: ...
    @property
    def data(self) -> np.ndarray: ...


class PointFieldMsg(Protocol):
    """``sensor_msgs/PointField``: a named field at a byte ``offset`` of each point."""

    @property
    def name(self) -> str: ...
    @property
    def offset(self) -> int: ...
    @property
    def datatype(self) -> int: ...


class PointCloud2Msg(_Grid, Protocol):
    """``sensor_msgs/PointCloud2``: ``height`` rows of ``width`` points, ``point_step`` bytes each."""

    @property
    def fields(self) -> Sequence[PointFieldMsg]: ...
    @property
    def is_bigendian(self) -> bool: ...
    @property
    def point_step(self) -> int: ...
    @property
    def row_step(self) -> int: ...
    @property
    def data(self) -> np.ndarray: ...


class CameraInfoMsg(_Grid, Protocol):
    """``sensor_msgs/CameraInfo`` (its matrices, ``K`` in ROS 1 and ``k`` in ROS 2, are read by name)."""

    @property
    def distortion_model(self) -> str: ...


class _Vector3(Protocol):
    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def z(self) -> float: ...


class _Quaternion(_Vector3, Protocol):
    @property
    def w(self) -> float: ...


class _Transform(Protocol):
    @property
    def translation(self) -> _Vector3: ...
    @property
    def rotation(self) -> _Quaternion: ...


class _TransformStamped(_Stamped, Protocol):
    @property
    def child_frame_id(self) -> str: ...
    @property
    def transform(self) -> _Transform: ...


class TFMessageMsg(Protocol):
    """``tf2_msgs/TFMessage``: ``geometry_msgs/TransformStamped`` edges."""

    @property
    def transforms(self) -> Sequence[_TransformStamped]: ...
