"""Transforms that change with time (``/tf``), indexed by stamp, over the static ones (``/tf_static``).

A :class:`TransformBuffer` holds every ``/tf`` edge ``(parent, child)`` as its samples sorted by stamp, and gives
the transform at any stamp between two samples: the translation interpolated linearly, the rotation by quaternion
slerp (:func:`interpolate_transform`). Beyond the first or last sample it extrapolates only within
:data:`EXTRAPOLATION_TOLERANCE_S` (the same straight line); farther, the edge has no transform at that stamp, as
tf2 refuses to extrapolate. :meth:`TransformBuffer.lookup` chains the edges of a stamp with the static tree
(:class:`~.tf.TransformTree`), e.g. ``T_odom_camera = T_odom_base(t) @ T_base_camera``: what poses a recording's
neighbouring frames (:meth:`semattnet.robotics.BagSource.views`).
"""

from __future__ import annotations

import os
from array import array
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from semattnet._errors import DataError
from semattnet.geometry import make_T

from .tf import NoTransformError, TransformTree, checked_transform, matrix_to_quaternion, quaternion_to_matrix

if TYPE_CHECKING:
    from .messages import TFMessageMsg

__all__ = [
    "EXTRAPOLATION_TOLERANCE_S",
    "TF_TOPIC",
    "TransformBuffer",
    "interpolate_transform",
    "read_tf_buffer",
    "slerp",
]

#: The topic of transforms that change with time (``tf2_msgs/TFMessage``).
TF_TOPIC = "/tf"
#: How far (seconds) before the first or after the last sample of an edge its transform is still extrapolated: a
#: camera and an odometry of the same rate are stamped some milliseconds apart, so the first or last image may fall
#: just outside the odometry's span; half a 10 Hz period at most.
EXTRAPOLATION_TOLERANCE_S = 0.05


def slerp(q0: Iterable[float], q1: Iterable[float], s: float) -> np.ndarray:
    """The unit quaternion ``(x, y, z, w)`` a share ``s`` of the way from ``q0`` to ``q1`` along the shorter arc
    (``s`` outside [0, 1] extrapolates along it)."""
    a, b = np.asarray(list(q0), dtype=np.float64), np.asarray(list(q1), dtype=np.float64)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    dot = float(a @ b)
    if dot < 0:  # q and -q are the same rotation: take the shorter way
        b, dot = -b, -dot
    if dot > 1 - 1e-12:
        q = a + s * (b - a)
    else:
        theta = np.arccos(dot)
        q = (np.sin((1 - s) * theta) * a + np.sin(s * theta) * b) / np.sin(theta)
    out: np.ndarray = q / np.linalg.norm(q)
    return out


def interpolate_transform(
    stamps: np.ndarray, translations: np.ndarray, quaternions: np.ndarray, stamp: int, tolerance_ns: int
) -> np.ndarray | None:
    """(4, 4) transform at ``stamp`` (ns) of samples sorted by ``stamps`` (N,), with ``translations`` (N, 3) and
    ``quaternions`` (N, 4) ``(x, y, z, w)``: linear in the translation, slerp in the rotation between the two samples
    around it; beyond the first or last sample by at most ``tolerance_ns``, the line through the two nearest (a
    single sample: itself); farther, None."""
    n = len(stamps)
    k = int(np.searchsorted(stamps, stamp))
    if k < n and stamps[k] == stamp:
        return make_T(quaternion_to_matrix(quaternions[k]), translations[k])
    outside = int(stamps[0]) - stamp if k == 0 else stamp - int(stamps[-1]) if k == n else 0
    if outside > tolerance_ns:
        return None
    if n == 1:
        return make_T(quaternion_to_matrix(quaternions[0]), translations[0])
    a = min(max(k - 1, 0), n - 2)
    s = (stamp - int(stamps[a])) / (int(stamps[a + 1]) - int(stamps[a]))
    t = (1 - s) * translations[a] + s * translations[a + 1]
    return make_T(quaternion_to_matrix(slerp(quaternions[a], quaternions[a + 1], s)), t)


@dataclass(frozen=True)
class _Track:
    """One ``/tf`` edge's samples, sorted by stamp (one per stamp: the last received)."""

    stamps: np.ndarray
    translations: np.ndarray
    quaternions: np.ndarray


class TransformBuffer:
    """``/tf`` edges by stamp over the ``static`` tree (module doc); ``source`` names it in errors, ``tolerance_s``
    the extrapolation allowed (:data:`EXTRAPOLATION_TOLERANCE_S`). ``skipped``: the errors of the transforms left
    out by :func:`read_tf_buffer`."""

    def __init__(
        self,
        static: TransformTree | None = None,
        source: str = TF_TOPIC,
        tolerance_s: float = EXTRAPOLATION_TOLERANCE_S,
    ) -> None:
        self.static = static if static is not None else TransformTree()
        self.source = source
        self.tolerance_ns = round(tolerance_s * 1e9)
        self.skipped: list[str] = []
        #: per edge, the stamps and the samples' 7 numbers (translation, quaternion), compact for a long recording
        self._samples: dict[tuple[str, str], tuple[array[int], array[float]]] = {}
        self._tracks: dict[tuple[str, str], _Track] | None = None

    def add(self, parent: str, child: str, stamp_ns: int, T_parent_child: np.ndarray) -> None:
        """Add a sample of the edge ``p_parent = T_parent_child @ p_child`` at ``stamp_ns``."""
        T = np.asarray(T_parent_child, dtype=np.float64)
        self._add(parent, child, stamp_ns, T[:3, 3], matrix_to_quaternion(T[:3, :3]))

    def _add(
        self, parent: str, child: str, stamp_ns: int, translation: Iterable[float], quaternion: Iterable[float]
    ) -> None:
        stamps, values = self._samples.setdefault((parent.lstrip("/"), child.lstrip("/")), (array("q"), array("d")))
        stamps.append(int(stamp_ns))
        values.extend([*map(float, translation), *map(float, quaternion)])
        self._tracks = None

    def add_message(self, msg: TFMessageMsg, where: str = "") -> None:
        """Add every ``geometry_msgs/TransformStamped`` of a ``tf2_msgs/TFMessage`` at its header stamp; a transform
        that is not one (:func:`~.tf.checked_transform`) is left out, its error kept in :attr:`skipped`."""
        for t in msg.transforms:
            parent, child = str(t.header.frame_id), str(t.child_frame_id)
            tr, rot = t.transform.translation, t.transform.rotation
            q = (rot.x, rot.y, rot.z, rot.w)
            try:
                checked_transform((tr.x, tr.y, tr.z), q)
            except DataError as exc:
                self.skipped.append(f"{where or self.source}: transform {parent!r} -> {child!r}: {exc}")
                continue
            stamp = int(t.header.stamp.sec) * 1_000_000_000 + int(t.header.stamp.nanosec)
            self._add(parent, child, stamp, (tr.x, tr.y, tr.z), np.asarray(q, dtype=np.float64) / np.linalg.norm(q))

    @property
    def tracks(self) -> dict[tuple[str, str], _Track]:
        """Every edge's samples, sorted by stamp (built once after the last :meth:`add`)."""
        if self._tracks is None:
            self._tracks = {}
            for key, (stamps, values) in self._samples.items():
                t = np.array(stamps, dtype=np.int64)
                v = np.array(values, dtype=np.float64).reshape(-1, 7)
                order = np.argsort(t, kind="stable")
                t, v = t[order], v[order]
                last = np.append(t[1:] != t[:-1], True)  # a repeated stamp: the last received
                self._tracks[key] = _Track(t[last], v[last, :3], v[last, 3:])
        return self._tracks

    def roots(self) -> list[str]:
        """The frames that are a ``/tf`` parent and no ``/tf`` child (``map``, ``odom``, ``world``), sorted."""
        parents, children = {p for p, _ in self.tracks}, {c for _, c in self.tracks}
        return sorted(parents - children)

    def at(self, parent: str, child: str, stamp_ns: int) -> np.ndarray | None:
        """(4, 4) ``T_parent_child`` of a ``/tf`` edge at ``stamp_ns`` (None: no such edge, or too far outside its
        samples)."""
        track = self.tracks.get((parent.lstrip("/"), child.lstrip("/")))
        if track is None:
            return None
        return interpolate_transform(
            track.stamps, track.translations, track.quaternions, int(stamp_ns), self.tolerance_ns
        )

    def tree_at(self, stamp_ns: int | None) -> TransformTree:
        """The static tree with every ``/tf`` edge that has a transform at ``stamp_ns`` (None: each edge's first
        sample, what tells whether a chain exists at all)."""
        tree = self.static.copy(f"{self.source} at {stamp_ns} ns" if stamp_ns is not None else self.source)
        for (parent, child), track in self.tracks.items():
            T = self.at(parent, child, int(track.stamps[0]) if stamp_ns is None else stamp_ns)
            if T is not None:
                tree.add(parent, child, T)
        return tree

    def lookup(self, target: str, source: str, stamp_ns: int) -> np.ndarray | None:
        """(4, 4) ``T_target_source`` at ``stamp_ns``, chained through ``/tf`` and the static tree; None when no
        chain joins them at that stamp (an edge of it too far outside its samples).

        Raises:
            DataError: two chains join them and disagree (:meth:`~.tf.TransformTree.lookup`).
        """
        try:
            return self.tree_at(stamp_ns).lookup(target, source)
        except NoTransformError:
            return None

    def fixed_frame(self, camera_frame: str, wanted: str | None = None) -> str:
        """The frame that poses ``camera_frame`` over time: ``wanted``, else ``odom`` when ``/tf`` names it, else the
        first root of ``/tf`` (:meth:`roots`) chained to the camera.

        Raises:
            NoTransformError: ``/tf`` is empty, or no chain joins the frame and the camera (naming both).
        """
        if not self.tracks:
            raise NoTransformError(f"{self.source}: no transform")
        named = {frame for edge in self.tracks for frame in edge}
        candidates = [wanted] if wanted is not None else ["odom"] if "odom" in named else self.roots()
        tree = self.tree_at(None)
        for frame in (c.lstrip("/") for c in candidates):
            try:
                if frame in named:
                    tree.lookup(frame, camera_frame)
                    return frame
            except NoTransformError:
                continue
        have = ", ".join(sorted(named))
        raise NoTransformError(
            f"{self.source}: no chain from {' or '.join(map(repr, candidates)) or 'a root frame'} "
            f"to the camera frame {camera_frame!r} (/tf frames: {have})"
        )


def read_tf_buffer(
    reader: Any, path: str | os.PathLike[str], tolerance_s: float = EXTRAPOLATION_TOLERANCE_S
) -> TransformBuffer:
    """Every ``/tf`` transform of an open bag (``reader``: :func:`~.reader.open_bag`'s) over its ``/tf_static``
    (:func:`~.reader.read_transforms`), in one pass over ``/tf``. A ``/tf`` message that cannot be deserialised, or a
    transform that is not one, is left out (its error in :attr:`TransformBuffer.skipped`).

    Raises:
        DataError: a bad ``/tf_static`` transform (naming it); a truncated or corrupt bag.
    """
    from .reader import message_errors, message_where, read_transforms

    buffer = TransformBuffer(read_transforms(reader, path), f"{path}: {TF_TOPIC}", tolerance_s)
    conns = [c for c in reader.connections if c.topic == TF_TOPIC]
    if not conns:  # (rosbags reads every topic when given no connection)
        return buffer
    for k, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
        where = message_where(TF_TOPIC, k, path)
        try:
            with message_errors(where):
                msg = reader.deserialize(raw, conn.msgtype)
        except DataError as exc:
            buffer.skipped.append(str(exc))
            continue
        buffer.add_message(msg, where)
    return buffer
