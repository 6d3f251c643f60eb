"""A small static transform tree (``/tf_static``) that chains transforms through intermediate frames.

An edge ``(parent, child, T_parent_child)`` maps child coordinates into the parent frame
(``p_parent = T_parent_child @ p_child``), as ``geometry_msgs/TransformStamped`` does (``header.frame_id`` =
parent, ``child_frame_id`` = child). :meth:`TransformTree.lookup` walks the tree in either direction, e.g.
``T_cam_lidar = T_cam_base @ T_base_lidar`` for ``velodyne -> base_link -> camera``. Frame names lose a
leading ``/`` (ROS 1 style). Quaternions are ``(x, y, z, w)`` as in ROS.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from typing import Any

import numpy as np

from semattnet._errors import DataError
from semattnet.geometry import invert_T, make_T

__all__ = ["NoTransformError", "TransformTree", "matrix_to_quaternion", "quaternion_to_matrix"]


class NoTransformError(DataError):
    """No chain of transforms joins two frames."""


def quaternion_to_matrix(q: Iterable[float]) -> np.ndarray:
    """(3, 3) rotation of a quaternion ``(x, y, z, w)`` (normalised first)."""
    x, y, z, w = np.asarray(list(q), dtype=np.float64) / np.linalg.norm(np.asarray(list(q), dtype=np.float64))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip


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


class TransformTree:
    """Static transforms between named frames; later edges for the same (parent, child) replace earlier ones."""

    def __init__(self, source: str = "/tf_static") -> None:
        self.source = source
        self._edges: dict[str, dict[str, np.ndarray]] = {}

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

    def add_message(self, msg: Any) -> None:
        """Add every ``geometry_msgs/TransformStamped`` of a ``tf2_msgs/TFMessage``."""
        for t in msg.transforms:
            tr, rot = t.transform.translation, t.transform.rotation
            R = quaternion_to_matrix((rot.x, rot.y, rot.z, rot.w))
            self.add(str(t.header.frame_id), str(t.child_frame_id), make_T(R, np.array([tr.x, tr.y, tr.z])))

    def lookup(self, target: str, source: str) -> np.ndarray:
        """(4, 4) ``T_target_source`` (``p_target = T @ p_source``), chained through intermediate frames.

        Raises:
            NoTransformError: no chain joins the frames; names both and the frames the tree has.
        """
        target, source = target.lstrip("/"), source.lstrip("/")
        if target == source:
            return np.eye(4)
        # breadth-first from source; T_node_source accumulates along the path
        seen: dict[str, np.ndarray] = {source: np.eye(4)} if source in self._edges else {}
        queue = deque(seen)
        while queue:
            node = queue.popleft()
            for nxt in self._edges[node]:
                if nxt not in seen:
                    seen[nxt] = self._edges[nxt][node] @ seen[node]
                    if nxt == target:
                        return seen[nxt]
                    queue.append(nxt)
        have = ", ".join(self.frames) or "none"
        raise NoTransformError(f"{self.source}: no transform between frames {source!r} and {target!r} "
                               f"(frames: {have})")  # fmt: skip
