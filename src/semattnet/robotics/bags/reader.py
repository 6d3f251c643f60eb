"""Opening a bag (ROS 1 ``.bag``, ROS 2 folder, or a bare ``.db3`` / ``.mcap`` file) through rosbags'
``AnyReader``, listing its topics, finding a topic's connections and reading ``/tf_static``.

Every rosbags, sqlite3 or decoding failure of a truncated or corrupt bag becomes one
:class:`~semattnet._errors.DataError` line naming the file (:func:`bag_errors`); every error about one message
starts with :func:`message_where`'s ``BAG: TOPIC message N`` (:func:`message_errors` for the reading failures).
"""

from __future__ import annotations

import functools
import os
import sqlite3
import struct
import zlib
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from semattnet._errors import DataError, SemAttNetError
from semattnet._utils.extras import require

from .deps import rosbags_typestore
from .tf import TransformTree

__all__ = [
    "TF_STATIC_TOPIC",
    "TopicRow",
    "bag_errors",
    "format_topics",
    "is_ros1",
    "list_topics",
    "message_errors",
    "message_where",
    "open_bag",
    "read_transforms",
    "topic_connections",
]

#: The topic of static transforms (``tf2_msgs/TFMessage``).
TF_STATIC_TOPIC = "/tf_static"


@dataclass(frozen=True)
class TopicRow:
    """One topic of a bag: its name, message type (``sensor_msgs/msg/Image``), message count and mean rate in Hz
    from the receive times (None with fewer than two messages)."""

    topic: str
    msgtype: str
    count: int
    rate_hz: float | None


@functools.cache
def _reader_errors() -> tuple[type[BaseException], ...]:
    rosbag1 = require("rosbags.rosbag1", "reading ROS bags")
    rosbag2 = require("rosbags.rosbag2", "reading ROS bags")
    highlevel = require("rosbags.highlevel", "reading ROS bags")
    serde = require("rosbags.serde", "reading ROS bags")
    return (
        highlevel.AnyReaderError,
        rosbag1.ReaderError,
        rosbag2.ReaderError,
        serde.SerdeError,
        sqlite3.Error,
        struct.error,
        EOFError,
        zlib.error,
        KeyError,
        IndexError,
        UnicodeDecodeError,
    )


@contextmanager
def _one_line(errors: tuple[type[BaseException], ...], what: str) -> Iterator[None]:
    """``errors`` raised in the block as one :class:`DataError` line ``WHAT: WHY`` (semattnet's own pass)."""
    try:
        yield
    except SemAttNetError:
        raise
    except errors as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise DataError(f"{what}: {why[:200]}") from None


def bag_errors(path: str | os.PathLike[str]) -> AbstractContextManager[None]:
    """Turn the failures of reading a truncated or corrupt bag into one :class:`DataError` line naming ``path``
    (semattnet's own errors pass through unchanged)."""
    return _one_line(_reader_errors(), f"{path}: cannot read the bag (truncated or corrupt?)")


def message_where(topic: str, index: int, path: str | os.PathLike[str] | None = None, noun: str = "message") -> str:
    """The start of every error about one message of a bag: ``BAG: TOPIC message N`` (N counts from 0 in the
    topic; ``noun`` "image" for the image topic, whose messages are the frames). Without ``path`` for a message
    named inside the error of the frame that needs it (``BAG: /cam image 3: /lidar message 3: ...``)."""
    return f"{'' if path is None else f'{path}: '}{topic} {noun} {index}"


def message_errors(where: str) -> AbstractContextManager[None]:
    """Turn the failures of deserialising one corrupt message into one :class:`DataError` line naming ``where``
    (:func:`message_where`, e.g. ``BAG: TOPIC image 3``), so the caller can fail that message alone (semattnet's
    errors pass through)."""
    errors = (*_reader_errors(), ValueError, TypeError, AttributeError)
    return _one_line(errors, f"{where}: cannot deserialise the message")


def is_ros1(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a ROS 1 bag (a ``.bag`` file); otherwise it is read as ROS 2."""
    return Path(path).suffix == ".bag" and Path(path).is_file()


@contextmanager
def open_bag(path: str | os.PathLike[str]) -> Iterator[Any]:
    """An open rosbags ``AnyReader`` of ``path``; reading errors inside the block name the file.

    Raises:
        DataError: ``path`` is missing, not a bag, truncated or corrupt.
    """
    highlevel = require("rosbags.highlevel", "reading ROS bags")
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: bag not found")
    with bag_errors(path):
        reader = highlevel.AnyReader([path], default_typestore=rosbags_typestore(is_ros1(path)))
        reader.open()
        try:
            yield reader
        finally:
            reader.close()


def topic_connections(reader: Any, topic: str, msgtypes: Sequence[str], path: str | os.PathLike[str]) -> list[Any]:
    """The reader's connections of ``topic``, checking that its type is one of ``msgtypes``.

    Raises:
        DataError: no such topic (the message lists those the bag has) or another message type.
    """
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        have = ", ".join(sorted({c.topic for c in reader.connections})) or "none"
        raise DataError(f"{path}: no topic {topic!r} (topics: {have})")
    bad = sorted({c.msgtype for c in conns if c.msgtype not in msgtypes})
    if bad:
        raise DataError(f"{path}: topic {topic!r} holds {bad[0]}, expected {' or '.join(msgtypes)}")
    return conns


def list_topics(path: str | os.PathLike[str]) -> list[TopicRow]:
    """Every topic of the bag at ``path`` with its type, count and rate (what ``--list-topics`` prints)."""
    with open_bag(path) as reader:
        rows = []
        for topic in sorted({c.topic for c in reader.connections}):
            conns = [c for c in reader.connections if c.topic == topic]
            times = [t for _, t, _ in reader.messages(connections=conns)]
            span = (max(times) - min(times)) / 1e9 if len(times) > 1 else 0.0
            rate = (len(times) - 1) / span if span > 0 else None
            rows.append(TopicRow(topic, conns[0].msgtype, len(times), rate))
    return rows


def format_topics(rows: Sequence[TopicRow]) -> str:
    """A plain-text table of :func:`list_topics` rows: topic, type, count, rate."""
    head = ("topic", "type", "count", "rate (Hz)")
    body = [(r.topic, r.msgtype, str(r.count), "-" if r.rate_hz is None else f"{r.rate_hz:.2f}") for r in rows]
    widths = [max(len(x[i]) for x in [head, *body]) for i in range(4)]

    def fmt(row: tuple[str, ...]) -> str:
        cells = (v.ljust(w) if i < 2 else v.rjust(w) for i, (v, w) in enumerate(zip(row, widths, strict=True)))
        return "  ".join(cells)

    return "\n".join(fmt(r) for r in [head, *body])


def read_transforms(reader: Any, path: str | os.PathLike[str], topic: str = TF_STATIC_TOPIC) -> TransformTree:
    """Every static transform of ``topic`` (none when the bag lacks it) as a :class:`TransformTree`.

    Raises:
        DataError: a message that cannot be deserialised or holds a transform that is not one (a NaN or infinite
            number, a quaternion far from unit length), naming the bag, the topic, the message and the frames.
    """
    tree = TransformTree(f"{path}: {topic}")
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:  # (rosbags reads every topic when given no connection)
        return tree
    for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
        where = message_where(topic, k, path)
        with message_errors(where):
            msg = reader.deserialize(raw, conn.msgtype)
        tree.add_message(msg, where)
    return tree
