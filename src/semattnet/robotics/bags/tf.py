"""A small static transform tree (``/tf_static``) that chains transforms through intermediate frames.

An edge ``(parent, child, T_parent_child)`` maps child coordinates into the parent frame
(``p_parent = T_parent_child @ p_child``), as ``geometry_msgs/TransformStamped`` does (``header.frame_id`` =
parent, ``child_frame_id`` = child). :meth:`TransformTree.lookup` walks the tree in either direction, e.g.
``T_cam_lidar = T_cam_base @ T_base_lidar`` for ``velodyne -> base_link -> camera``. Frame names lose a
leading ``/`` (ROS 1 style). Quaternions are ``(x, y, z, w)`` as in ROS.

A transform read from a message is refused (one :class:`DataError` naming the message and both frames) when a
number is NaN or infinite or its quaternion is not unit length within :data:`QUATERNION_NORM_TOLERANCE` (a zero
quaternion is no rotation; tf2 refuses such transforms too). Two chains between the same frames that disagree
(a cycle in the tree) are refused when looked up, naming both, rather than one of them picked.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import DataError
from semattnet.geometry import invert_T, make_T

if TYPE_CHECKING:
    from .messages import TFMessageMsg

__all__ = [
    "QUATERNION_NORM_TOLERANCE",
    "NoTransformError",
    "TransformTree",
    "checked_transform",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
]

#: How far from 1 a transform's quaternion norm may be (rounding in a launch file); farther is refused.
QUATERNION_NORM_TOLERANCE = 1e-3
#: Two chains between the same frames agree within this many metres and radians.
_AGREE_M, _AGREE_RAD = 1e-3, 2e-3
#: Chains compared per lookup at most (a static tree has one; a cycle adds a few).
_MAX_CHAINS = 16
#: Frames a transform tree holds at most (a robot's static tree has tens; a peer naming thousands is refused).
MAX_FRAMES = 512
#: Frames an error message lists at most (the rest counted).
_LISTED = 20


class NoTransformError(DataError):
    """No chain of transforms joins two frames."""


def quaternion_to_matrix(q: Iterable[float]) -> np.ndarray:
    """(3, 3) rotation of a quaternion ``(x, y, z, w)`` (normalised first)."""
    x, y, z, w = np.asarray(list(q), dtype=np.float64) / np.linalg.norm(np.asarray(list(q), dtype=np.float64))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)``, ``w >= 0``, of the rotation nearest to ``R`` (3, 3) (SVD projection, so a
    slightly non-orthonormal calibration such as KITTI's is handled), by Shepperd's method."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    t = np.trace(R)
    if t > max(R[0, 0], R[1, 1], R[2, 2]):
        w = 0.5 * np.sqrt(1 + t)
        q = np.array([(R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w), w])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2 * np.sqrt(1 + R[i, i] - R[j, j] - R[k, k])
        q = np.zeros(4)
        q[i], q[j], q[k] = s / 4, (R[j, i] + R[i, j]) / s, (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    q = q / np.linalg.norm(q)
    q = -q if q[3] < 0 else q
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def _numbers(values: Iterable[float]) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


def checked_transform(translation: Iterable[float], quaternion: Iterable[float]) -> np.ndarray:
    """(4, 4) transform of a translation ``(x, y, z)`` and a quaternion ``(x, y, z, w)`` (normalised).

    Raises:
        DataError: a NaN or infinite number, or a quaternion norm off 1 by more than
            :data:`QUATERNION_NORM_TOLERANCE`; the message says which and the numbers (the caller names where).
    """
    t, q = np.asarray(list(translation), dtype=np.float64), np.asarray(list(quaternion), dtype=np.float64)
    if not np.isfinite(t).all():
        raise DataError(f"translation (x, y, z) = {_numbers(t)} is not finite")
    if not np.isfinite(q).all():
        raise DataError(f"rotation quaternion (x, y, z, w) = {_numbers(q)} is not finite")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise DataError(
            f"rotation quaternion (x, y, z, w) = {_numbers(q)} has norm {norm:.6g}; a rotation's has "
            f"norm 1 (within {QUATERNION_NORM_TOLERANCE:g})"
        )
    return make_T(quaternion_to_matrix(q), t)


def _disagreement(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """(metres, radians) between two rigid transforms."""
    D = invert_T(A) @ B
    angle = float(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), angle


class TransformTree:
    """Static transforms between named frames; later edges for the same (parent, child) replace earlier ones."""

    def __init__(self, source: str = "/tf_static") -> None:
        self.source = source
        self._edges: dict[str, dict[str, np.ndarray]] = {}

    def copy(self, source: str | None = None) -> TransformTree:
        """A tree with the same edges (adding to it leaves this one unchanged), its errors naming ``source``."""
        tree = TransformTree(self.source if source is None else source)
        tree._edges = {frame: dict(edges) for frame, edges in self._edges.items()}
        return tree

    @property
    def frames(self) -> list[str]:
        """Every frame named by an edge, sorted."""
        return sorted(self._edges)

    def add(self, parent: str, child: str, T_parent_child: np.ndarray) -> None:
        """Add the edge ``p_parent = T_parent_child @ p_child`` (and its inverse for walking back)."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        T = np.asarray(T_parent_child, dtype=np.float64)
        self._edges.setdefault(parent, {})[child] = T
        self._edges.setdefault(child, {})[parent] = invert_T(T)

    def add_message(self, msg: TFMessageMsg, where: str = "") -> None:
        """Add every ``geometry_msgs/TransformStamped`` of a ``tf2_msgs/TFMessage``.

        Raises:
            DataError: a transform :func:`checked_transform` refuses: ``WHERE: transform 'PARENT' -> 'CHILD': WHY``;
                or the message would bring the tree beyond :data:`MAX_FRAMES` frames (nothing of it added).
        """
        transforms = list(msg.transforms)
        named = {f for t in transforms for f in (str(t.header.frame_id).lstrip("/"), str(t.child_frame_id).lstrip("/"))}
        new = named - set(self._edges)
        if len(self._edges) + len(new) > MAX_FRAMES:
            raise DataError(
                f"{where or self.source}: {len(transforms)} transform(s) naming {len(new)} new frame(s), beyond the "
                f"{MAX_FRAMES} frames a tree holds (it has {len(self._edges)}); the message is refused"
            )
        for t in transforms:
            parent, child = str(t.header.frame_id), str(t.child_frame_id)
            tr, rot = t.transform.translation, t.transform.rotation
            try:
                T = checked_transform((tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w))
            except DataError as exc:
                raise DataError(f"{where or self.source}: transform {parent!r} -> {child!r}: {exc}") from None
            self.add(parent, child, T)

    def _chains(self, source: str, target: str) -> list[list[str]]:
        """The simple chains of frames from ``source`` to ``target`` (at most :data:`_MAX_CHAINS`), shortest first."""
        found: list[list[str]] = []
        if target not in self._edges:  # a frame the tree does not have: no search
            return found
        stack: list[tuple[str, list[str]]] = [(source, [source])] if source in self._edges else []
        steps = 0
        while stack and len(found) < _MAX_CHAINS and steps < 100 * _MAX_CHAINS * len(self._edges):
            node, chain = stack.pop()
            steps += 1
            for nxt in sorted(self._edges[node], reverse=True):
                if nxt == target:
                    found.append([*chain, nxt])
                elif nxt not in chain:
                    stack.append((nxt, [*chain, nxt]))
        return sorted(found, key=lambda c: (len(c), c))

    def _chained(self, chain: list[str]) -> np.ndarray:
        """``T_last_first`` along ``chain`` (``p_last = T @ p_first``)."""
        T = np.eye(4)
        for a, b in itertools.pairwise(chain):
            T = self._edges[b][a] @ T
        return T

    def lookup(self, target: str, source: str) -> np.ndarray:
        """(4, 4) ``T_target_source`` (``p_target = T @ p_source``), chained through intermediate frames.

        Raises:
            NoTransformError: no chain joins the frames; names both and the frames the tree has.
            DataError: two chains join them and disagree (more than 1 mm or 0.1 degree); names both chains.
        """
        target, source = target.lstrip("/"), source.lstrip("/")
        if target == source:
            return np.eye(4)
        chains = self._chains(source, target)
        if not chains:
            frames = self.frames
            have = ", ".join(frames[:_LISTED]) or "none"
            if len(frames) > _LISTED:
                have += f" and {len(frames) - _LISTED} more"
            raise NoTransformError(
                f"{self.source}: no transform between frames {source!r} and {target!r} (frames: {have})"
            )
        T = self._chained(chains[0])
        for other in chains[1:]:
            metres, radians = _disagreement(T, self._chained(other))
            if metres > _AGREE_M or radians > _AGREE_RAD:
                raise DataError(
                    f"{self.source}: two different transforms from frame {source!r} to {target!r}: "
                    f"{' -> '.join(chains[0])} and {' -> '.join(other)} (they differ by {metres:.3g} m "
                    f"and {np.degrees(radians):.3g} degrees); the static transforms must join two "
                    "frames by one chain"
                )
        return T
