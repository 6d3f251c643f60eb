"""The node's log on ``/rosout``, as ``rclcpp`` and ``rospy`` nodes publish theirs (``rqt_console``, ``ros2 topic
echo /rosout``, roscore's ``rosout`` node read it).

What goes there: the node's report lines (INFO) and what the node's loggers say (:data:`LOGGERS`: a frame that
cannot be completed, a bad message, a peer that stalls, a viewer that will not close: INFO and above, as
logged). ROS 2:
``rcl_interfaces/msg/Log`` with rcl's levels (10 DEBUG ... 50 FATAL), ``name`` the node's logger name
(``robot.depth`` for ``/robot/depth``), on rcl's ``/rosout`` QoS (reliable, transient local, keep-last 1000:
a late ``rqt_console`` gets the last 1000 lines). ROS 1: ``rosgraph_msgs/Log`` with rospy's levels (1 DEBUG ...
16 FATAL), ``name`` the node's name, its published topics in ``topics``.

Records are queued by a :class:`logging.Handler` from whatever thread logs them (at most :data:`MAX_QUEUED`;
older ones are counted and dropped, never memory without bound) and published by the node's loop thread
(:meth:`Rosout.publish_pending`, each tick and on stop), so the transport is used from one thread; the handler
is attached while the node's loop runs. The terminal keeps every line it had. A record
logged while publishing (a failed publish's own warning) is not queued again. ``--ros-args
--disable-rosout-logs`` turns it off.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Sequence
from typing import TYPE_CHECKING

from .transport import QoS, Transport

if TYPE_CHECKING:
    from semattnet.robotics.bags.deps import Typestore

    from .transport import Publisher

__all__ = ["LOGGERS", "MAX_QUEUED", "ROSOUT_QOS", "ROSOUT_TOPIC", "Rosout", "logger_name"]

#: The topic (absolute: every node's log goes to the one ``/rosout``).
ROSOUT_TOPIC = "/rosout"
#: rcl's ``/rosout`` QoS: reliable, transient local, keep-last 1000.
ROSOUT_QOS = QoS(reliable=True, depth=1000, durable=True)
#: The loggers whose records go to ``/rosout``: the node's and its transports'.
LOGGERS = ("semattnet.ros", "semattnet.robotics")
#: Records waiting for the loop thread at most; beyond, the oldest are dropped and counted.
MAX_QUEUED = 1000
#: Python's levels -> (rcl_interfaces/Log, rosgraph_msgs/Log) levels.
_LEVELS = ((logging.CRITICAL, 50, 16), (logging.ERROR, 40, 8), (logging.WARNING, 30, 4), (logging.INFO, 20, 2))
_DEBUG = (10, 1)


def logger_name(node_name: str) -> str:
    """rcl's logger name of a node: its fully qualified name without the leading slash, dots for slashes
    (``/robot/depth`` -> ``robot.depth``)."""
    return node_name.strip("/").replace("/", ".")


def _ros_level(levelno: int, ros1: bool) -> int:
    for at_least, ros2_level, ros1_level in _LEVELS:
        if levelno >= at_least:
            return ros1_level if ros1 else ros2_level
    return _DEBUG[1] if ros1 else _DEBUG[0]


class Rosout(logging.Handler):
    """Publishes log records on ``/rosout`` (module doc) for the node named ``node_name`` (fully qualified,
    ``/robot/depth``); ``topics``: the node's published topics (ROS 1's ``topics`` field)."""

    def __init__(self, transport: Transport, node_name: str, topics: Sequence[str] = ()) -> None:
        super().__init__(logging.INFO)
        self.transport, self.node_name, self.topics = transport, node_name, list(topics)
        ts: Typestore = transport.typestore  # type: ignore[assignment]
        types = ts.types
        self.ros1 = "rcl_interfaces/msg/Log" not in types and "rosgraph_msgs/msg/Log" in types
        self.msgtype = "rosgraph_msgs/msg/Log" if self.ros1 else "rcl_interfaces/msg/Log"
        self.publisher: Publisher | None = None
        self.dropped = 0  # records dropped from a full queue
        self._queue: deque[logging.LogRecord] = deque(maxlen=MAX_QUEUED)  # a full one drops its oldest
        self._guard = threading.Lock()
        self._publishing = threading.local()
        self._echo: list[logging.Logger] = []  # loggers given logging.lastResort by attach()

    def advertise(self) -> None:
        """Advertise ``/rosout``."""
        self.publisher = self.transport.advertise(ROSOUT_TOPIC, self.msgtype, ROSOUT_QOS)

    def attach(self) -> None:
        """Take the records of :data:`LOGGERS` (until :meth:`detach`). Where no handler was configured (Python then
        writes warnings to stderr through :data:`logging.lastResort`), that one is attached beside it, so the
        terminal keeps its lines."""
        self._echo = []
        for name in LOGGERS:
            logger = logging.getLogger(name)
            if not logger.hasHandlers() and logging.lastResort is not None:
                logger.addHandler(logging.lastResort)
                self._echo.append(logger)
            logger.addHandler(self)

    def detach(self) -> None:
        """Stop taking records (what is queued is dropped); the loggers as they were."""
        for name in LOGGERS:
            logging.getLogger(name).removeHandler(self)
        for logger in self._echo:
            if logging.lastResort is not None:
                logger.removeHandler(logging.lastResort)
        self._echo = []
        self.close()

    def emit(self, record: logging.LogRecord) -> None:
        """Queue ``record`` for the loop thread (any thread; never blocks, never raises)."""
        if getattr(self._publishing, "active", False):
            return
        with self._guard:
            if len(self._queue) == MAX_QUEUED:  # the append drops the oldest
                self.dropped += 1
            self._queue.append(record)

    def line(self, text: str, level: int = logging.INFO) -> None:
        """Queue one line of the node's own (a report line) at ``level``."""
        record = logging.LogRecord("semattnet.ros", level, "", 0, text, None, None, func="report")
        self.emit(record)

    def publish_pending(self) -> int:
        """Publish the queued records (the loop thread); how many."""
        with self._guard:
            records = list(self._queue)
            self._queue.clear()
        if self.publisher is None or not records:
            return 0
        self._publishing.active = True
        try:
            for record in records:
                self.publisher.publish(self.message(record))
        except Exception as exc:  # the log never stops the node: one line (on stderr, not queued again)
            logging.getLogger("semattnet.ros").warning("/rosout: not published (%s: %s)", type(exc).__name__, exc)
        finally:
            self._publishing.active = False
        return len(records)

    def message(self, record: logging.LogRecord) -> object:
        """``record`` as the transport's Log message."""
        ts: Typestore = self.transport.typestore  # type: ignore[assignment]
        types = ts.types
        level = _ros_level(record.levelno, self.ros1)
        ns = int(record.created * 1e9)
        stamp = types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        fields = {
            "level": level,
            "msg": record.getMessage(),
            "file": record.pathname,
            "function": record.funcName or "",
            "line": max(0, int(record.lineno or 0)),
        }
        if self.ros1:
            header = types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="")
            return types[self.msgtype](header=header, name=self.node_name, topics=self.topics, **fields)
        return types[self.msgtype](stamp=stamp, name=logger_name(self.node_name), **fields)

    def close(self) -> None:
        """Stop queueing (the handler is removed from its logger by the node)."""
        with self._guard:
            self._queue.clear()
        super().close()
