"""What a live node did with its inputs, as one typed snapshot (:class:`NodeStatus`): per input topic what was
received, decoded, lost before pairing, stale, completed and failed, the kernel's UDP receive drops of the
process's sockets and the loop's stage tally. The node's report line is made from it; a diagnostics publisher
reads the same fields.

Every image received is accounted for: ``received = completed + failed + stale + lost + in_flight``
(:attr:`NodeStatus.accounted`), ``in_flight`` the images waiting to be paired, the pair in the slot and the frame
in the worker.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from semattnet.inference.timing import StageTally

__all__ = ["NodeStatus", "TopicCounts", "TopicStatus", "udp_drops"]


@dataclass
class TopicCounts:
    """One input topic's running counts (kept by :class:`~.inputs.PairingInputs`): messages received, decoded,
    refused (``bad``: not decodable, one logged line each) and lost before pairing (overtaken in the buffers by a
    newer one, or no partner within the max skew)."""

    received: int = 0
    decoded: int = 0
    bad: int = 0
    lost: int = 0


@dataclass(frozen=True)
class TopicStatus:
    """One input topic in a :class:`NodeStatus`: :class:`TopicCounts` and, for the paired topics (image, scan),
    what became of the pairs they were in (``stale``: replaced in the slot by a newer pair; ``completed``;
    ``failed``)."""

    received: int
    decoded: int
    bad: int
    lost: int
    stale: int = 0
    completed: int = 0
    failed: int = 0


@dataclass(frozen=True)
class NodeStatus:
    """A snapshot of a live node (module doc).

    Attributes:
        topics: by role (``image``, ``scan``, ``camera_info``, ``tf_static``, ``tf``), the topics subscribed.
        completed: frames published. failed: frames that could not be completed (one line each).
        stale: pairs replaced in the slot by a newer one while the completer was busy.
        lost: images lost before pairing. in_flight: images waiting, in the slot or in the worker.
        socket_drops: datagrams the kernel dropped at the process's UDP sockets (a full receive buffer), None where
            not known (not Linux, or a TCP transport).
        tally: the loop's stage times (read with its ``line``).
    """

    topics: Mapping[str, TopicStatus]
    completed: int
    failed: int
    stale: int
    lost: int
    in_flight: int
    socket_drops: int | None
    tally: StageTally

    @property
    def received(self) -> int:
        """Images received."""
        image = self.topics.get("image")
        return 0 if image is None else image.received

    @property
    def bad(self) -> int:
        """Messages refused, all topics."""
        return sum(t.bad for t in self.topics.values())

    @property
    def accounted(self) -> bool:
        """Whether every image received is completed, failed, stale, lost or in flight."""
        return self.received == self.completed + self.failed + self.stale + self.lost + self.in_flight

    def line(self, final: bool = False) -> str:
        """The report line: what became of the images received, the bad messages and the socket drops, then the
        stage times (since the last line; ``final``: in total)."""
        head = "ros node stopped: " if final else "ros node: "
        drops = "" if self.socket_drops is None else f", {self.socket_drops} datagram(s) dropped at the socket"
        return (
            f"{head}{self.completed} frame(s) published, {self.stale} stale pair(s) dropped, {self.lost} image(s) "
            f"without a scan, {self.failed} frame(s) failed, {self.bad} bad message(s); {self.received} image(s) "
            f"received, {self.in_flight} in flight{drops}; {self.tally.line(total=final)}"
        )


def _socket_inodes() -> set[str]:
    """The inodes of the process's sockets (``/proc/self/fd``: ``socket:[INODE]``)."""
    inodes = set()
    fds = Path("/proc/self/fd")
    for fd in os.listdir(fds):
        try:
            target = os.readlink(fds / fd)
        except OSError:  # closed meanwhile
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    return inodes


def udp_drops() -> int | None:
    """Datagrams the kernel dropped at this process's UDP sockets (IPv4 and IPv6) since they were opened: the
    ``drops`` column of ``/proc/self/net/udp`` and ``udp6`` for the process's socket inodes. None off Linux."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        mine = _socket_inodes()
        total = 0
        for table in ("udp", "udp6"):
            path = Path("/proc/self/net") / table
            if not path.exists():
                continue
            for line in path.read_text().splitlines()[1:]:
                row = line.split()  # sl local rem st tx:rx tr:tm retrnsmt uid timeout inode ref pointer drops
                if len(row) >= 13 and row[9] in mine:
                    total += int(row[12])
        return total
    except (OSError, ValueError):
        return None
