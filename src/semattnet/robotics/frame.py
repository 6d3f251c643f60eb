"""One completed frame as every robot output sends it, and the one table of their topic names.

:class:`RobotFrame` is built once per completed frame (:meth:`RobotFrame.of`): the input's stamp and frame
ids, the stored depth as ``32FC1`` metres with holes NaN (REP 118), its uncertainty, the coloured cloud in the
camera frame (the pixels ``max_uncertainty`` rejects left out), the CameraInfo and ``T_cam_lidar``.
:meth:`RobotFrame.messages` turns it into ROS messages (``rosbags`` objects of a type store); the bag
(``--bag-out``) writes them and the live ROS nodes publish them. The live Foxglove view (``--live``) and the
Rerun recording send its cloud.

:data:`TOPICS` names every output topic by role. A bag or the Foxglove view puts them under their prefix
(``/semattnet/depth_image``); a ROS node under ``~/output`` (``/NAMESPACE/semattnet/output/depth_image``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import InputError
from semattnet.geometry.cameras import CameraInfoData

if TYPE_CHECKING:
    from semattnet.data.frames import Frame
    from semattnet.geometry import PointCloud
    from semattnet.inference.sinks import Prediction
    from semattnet.inference.uncertainty import UncertaintyLimit
    from semattnet.robotics.bags.deps import Typestore

__all__ = [
    "ROS_TYPES",
    "TOPICS",
    "RobotFrame",
    "cloud_rays",
    "frame_camera",
    "pinhole_info",
    "stamp_ns",
    "strided_cloud",
    "topic_names",
]

#: Output topic names by role, relative to an output's prefix (one table for the bag, Foxglove and ROS).
TOPICS = {
    "depth": "depth_image",
    "points": "point_cloud",
    "uncertainty": "uncertainty",
    "camera_info": "camera_info",
    "latency": "latency",
}
#: The ROS message type of each role :meth:`RobotFrame.messages` builds.
ROS_TYPES = {
    "depth": "sensor_msgs/msg/Image",
    "points": "sensor_msgs/msg/PointCloud2",
    "uncertainty": "sensor_msgs/msg/Image",
    "camera_info": "sensor_msgs/msg/CameraInfo",
}


def topic_names(prefix: str, roles: tuple[str, ...] | None = None) -> dict[str, str]:
    """``{role: PREFIX/NAME}`` of :data:`TOPICS` (``roles``: those only)."""
    base = prefix.rstrip("/")
    return {k: f"{base}/{v}" for k, v in TOPICS.items() if roles is None or k in roles}


def stamp_ns(frame: Frame, index: int) -> int:
    """A frame's sensor time in ns: its ``meta.stamp_ns``, else its ``timestamp``, else ``index`` x 0.1 s."""
    if frame.meta.stamp_ns is not None:
        return int(frame.meta.stamp_ns)
    if frame.timestamp is not None:
        return round(frame.timestamp * 1e9)
    return index * 100_000_000


def pinhole_info(K: np.ndarray, width: int, height: int) -> CameraInfoData:
    """A distortion-free CameraInfo of intrinsics ``K`` for a ``width`` x ``height`` image (frame id ``camera``)."""
    K = np.asarray(K, dtype=np.float64)
    return CameraInfoData(
        width, height, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", "camera"
    )


def frame_camera(frame: Frame) -> tuple[str, CameraInfoData | None]:
    """The camera frame id (``meta.frame_id``, else the CameraInfo's, else ``camera``) and the CameraInfo
    (``meta.camera_info``, else a distortion-free one of ``K`` and the image size; None without either)."""
    meta, K = frame.meta, frame.K
    info = meta.camera_info
    if info is None and K is not None:
        h, w = frame.size
        info = pinhole_info(K, w, h)
    frame_id = meta.frame_id or (info.frame_id if info is not None else "") or "camera"
    return str(frame_id), info


def _nan_holes(depth: np.ndarray) -> np.ndarray:
    """float32 metres with every hole (<= 0 or infinite) NaN; NaN stays NaN (no copy when there is no other)."""
    d = np.asarray(depth, dtype=np.float32)
    bad = (d <= 0) | (d == np.inf)  # NaN compares False: already a hole
    return np.where(bad, np.float32(np.nan), d) if bad.any() else d


#: The rays of :func:`cloud_rays` by (K, height, width, stride): a node's camera needs one entry, a few at most.
_RAYS: dict[tuple[bytes, int, int, int], np.ndarray] = {}
_MAX_RAYS = 8


def cloud_rays(K: np.ndarray, height: int, width: int, stride: int = 1) -> np.ndarray:
    """(ceil(H / stride) * ceil(W / stride), 3) float32 rays ``(x / z, y / z, 1)`` of every ``stride``-th pixel in
    both directions, row-major (pixel centres at integer coordinates, skew honoured as
    :func:`~semattnet.geometry.depth_to_points` does): a pixel of depth ``z`` is the point ``z`` times its ray.
    Computed once per (K, size, stride), cached, read-only."""
    K = np.asarray(K, dtype=np.float64)
    key = (K.tobytes(), int(height), int(width), int(stride))
    rays = _RAYS.get(key)
    if rays is None:
        v, u = np.mgrid[0:height:stride, 0:width:stride].astype(np.float64)
        b = (v - K[1, 2]) / K[1, 1]
        a = (u - K[0, 2] - K[0, 1] * b) / K[0, 0]
        rays = np.stack([a, b, np.ones_like(a)], -1).reshape(-1, 3).astype(np.float32)
        rays.flags.writeable = False
        if len(_RAYS) >= _MAX_RAYS:
            _RAYS.pop(next(iter(_RAYS)))
        _RAYS[key] = rays
    return rays


def strided_cloud(
    depth: np.ndarray,
    K: np.ndarray,
    stride: int,
    rgb: np.ndarray | None = None,
    keep: np.ndarray | None = None,
    max_depth: float | None = None,
    frame: str = "cam",
) -> PointCloud:
    """The cloud of every ``stride``-th pixel of ``depth`` (H, W) metres (NaN or <= 0: none) in both directions,
    from the cached :func:`cloud_rays`; ``rgb`` its colours, ``keep`` (H, W) bool the pixels it may keep,
    ``max_depth`` leaves out deeper ones. Vectorised by flat pixel indices (``take``, not boolean masks of
    (H, W, 3) arrays: several times faster)."""
    from semattnet.geometry import PointCloud

    if stride < 1:
        raise InputError(f"cloud stride: expected a positive number of pixels, got {stride}")
    h, w = depth.shape
    d = depth[::stride, ::stride]
    with np.errstate(invalid="ignore"):
        sel = np.isfinite(d) & (d > 0)
        if max_depth is not None:
            sel &= d <= max_depth
    if keep is not None:
        sel &= np.asarray(keep, dtype=bool)[::stride, ::stride]
    idx = np.flatnonzero(sel)
    z = np.ascontiguousarray(d).reshape(-1).take(idx).astype(np.float32, copy=False)
    xyz = cloud_rays(K, h, w, stride).take(idx, axis=0)
    xyz *= z[:, None]
    colours = None
    if rgb is not None:
        colours = np.ascontiguousarray(np.asarray(rgb, dtype=np.uint8)[::stride, ::stride]).reshape(-1, 3).take(idx, 0)
    return PointCloud(xyz, colours, frame=frame)


@dataclass(frozen=True)
class RobotFrame:
    """One completed frame, ready to send (module doc).

    Attributes:
        stamp_ns: the input image's header stamp. frame_id: the camera frame id. lidar_frame_id: the LiDAR's
            (``""``: unknown). depth: (H, W) float32 metres, NaN = no depth. uncertainty: (H, W) float32 metres,
            NaN = none, or None. cloud: the coloured cloud (camera frame). camera_info: the input's CameraInfo.
        T_cam_lidar: (4, 4) LiDAR -> camera, or None.
    """

    stamp_ns: int
    frame_id: str
    lidar_frame_id: str
    depth: np.ndarray
    uncertainty: np.ndarray | None
    cloud: PointCloud
    camera_info: CameraInfoData
    T_cam_lidar: np.ndarray | None = None

    @classmethod
    def build(
        cls,
        stamp: int,
        frame_id: str,
        depth: np.ndarray,
        info: CameraInfoData,
        rgb: np.ndarray | None = None,
        K: np.ndarray | None = None,
        uncertainty: np.ndarray | None = None,
        keep: np.ndarray | None = None,
        max_depth: float | None = None,
        cloud_stride: int | None = None,
    ) -> RobotFrame:
        """A frame of arrays: ``depth`` (H, W) metres (<= 0 or NaN = hole) of ``info``'s size, ``rgb`` the
        cloud's colours, ``K`` (default ``info``'s), ``keep`` the pixels the cloud keeps (default all);
        ``cloud_stride``: None every pixel (:func:`~semattnet.geometry.depth_to_points`), N every N-th pixel both
        ways (:func:`strided_cloud`), 0 no cloud (an empty one)."""
        from semattnet.geometry import PointCloud, depth_to_points

        d = _nan_holes(depth)
        if d.shape != (info.height, info.width):
            raise InputError(f"depth: shape {d.shape} differs from the CameraInfo's {info.height}x{info.width}")
        unc = None if uncertainty is None else _nan_holes(uncertainty)
        if unc is not None and unc.shape != d.shape:
            raise InputError(f"uncertainty: shape {unc.shape} differs from the depth's {d.shape}")
        K = info.intrinsics() if K is None else np.asarray(K, dtype=np.float64)
        if cloud_stride is None:
            cloud = depth_to_points(np.nan_to_num(d, nan=0.0), K, rgb, mask=keep, max_depth=max_depth, frame=frame_id)
        elif cloud_stride == 0:
            none = np.zeros((0, 3), np.float32)
            cloud = PointCloud(none, None if rgb is None else none.astype(np.uint8), frame=frame_id)
        else:
            cloud = strided_cloud(d, K, cloud_stride, rgb, keep, max_depth, frame_id)
        return cls(int(stamp), frame_id, "", d, unc, cloud, info)

    @staticmethod
    def reads(uncertainty: bool = False, max_uncertainty: UncertaintyLimit | None = None) -> frozenset[str]:
        """What :meth:`of` reads of a completion with these options (:meth:`~semattnet.inference.sinks.Sink.reads`):
        the final depth, and the uncertainty when it is sent or limits the cloud."""
        from semattnet.models.outputs import DEPTH_OUTPUTS

        return DEPTH_OUTPUTS | ({"uncertainty"} if uncertainty or max_uncertainty is not None else set())

    @classmethod
    def of(
        cls,
        pred: Prediction,
        index: int = 0,
        uncertainty: bool = False,
        max_depth: float | None = None,
        max_uncertainty: UncertaintyLimit | None = None,
        output: str = "a robot output",
        float_depth: bool = False,
        cloud_stride: int | None = None,
    ) -> RobotFrame:
        """The frame of a prediction: the stored depth (and, with ``uncertainty``, the stored uncertainty);
        ``float_depth``: the float depth and uncertainty instead (``pred.depth``, what ``predict --npy`` writes,
        not quantised to the PNG's 1/256 m: a live node's); ``cloud_stride``: see :meth:`build`; ``output`` names
        what needs it in the errors."""
        from dataclasses import replace

        frame = pred.frame
        if frame.K is None:
            raise InputError(f"{frame.name}: {output} needs the frame's intrinsics K, none given")
        frame_id, info = frame_camera(frame)
        assert info is not None  # K is known
        unc = None
        if uncertainty:
            unc = pred.uncertainty if float_depth else pred.uncertainty_stored
            if unc is None:
                raise InputError(f"{frame.name}: --uncertainty: the method gives no per-pixel uncertainty")
        out = cls.build(
            stamp_ns(frame, index),
            frame_id,
            pred.depth if float_depth else pred.stored,
            info,
            rgb=frame.rgb,
            K=frame.K,
            uncertainty=unc,
            keep=pred.keep(max_uncertainty),
            max_depth=max_depth,
            cloud_stride=cloud_stride,
        )
        T = None if frame.calib is None else np.asarray(frame.calib.T_cam_lidar, dtype=np.float64)
        return replace(out, lidar_frame_id=frame.meta.lidar_frame_id, T_cam_lidar=T)

    def messages(self, ts: Typestore, roles: frozenset[str] | None = None) -> dict[str, object]:
        """``{role: message}`` (:data:`ROS_TYPES`; ``uncertainty`` only when the frame has one; ``roles``: those
        only), all stamped with the input's stamp and frame id."""
        from semattnet.robotics.bags.encode import (
            camera_info_message,
            depth_image_message,
            pack_rgb,
            pointcloud2_message,
        )

        t, fid, xyz = self.stamp_ns, self.frame_id, self.cloud.xyz
        want = frozenset(ROS_TYPES) if roles is None else roles
        out: dict[str, object] = {}
        if "depth" in want:
            out["depth"] = depth_image_message(ts, self.depth, t, fid)
        if self.uncertainty is not None and "uncertainty" in want:
            out["uncertainty"] = depth_image_message(ts, self.uncertainty, t, fid)
        if "points" in want:
            fields = {"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}
            if self.cloud.rgb is not None:
                fields["rgb"] = pack_rgb(self.cloud.rgb)
            out["points"] = pointcloud2_message(ts, fields, t, fid)
        if "camera_info" in want:
            out["camera_info"] = camera_info_message(ts, self.camera_info, t, fid)
        return out
