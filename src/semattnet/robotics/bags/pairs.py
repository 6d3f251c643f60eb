"""Image + LiDAR scan pairs from a bag, with their calibration: what a bag frame source yields.

:class:`BagPairs` checks everything it can before the first frame (topics and types, the pairing, the
calibration: ``CameraInfo`` + ``/tf_static``, or a rig that overrides both) in one pass over the headers,
then yields, in a second pass, one outcome per image of the image topic, in order: a :class:`BagPair`, or a
:class:`BagFailure` carrying that image's one-line :class:`~semattnet._errors.DataError` (no scan within the
max skew, an undecodable image, scan or CameraInfo, an image size the calibration disagrees with). A bad message
fails only the images that need it and never ends the pass; every error names the bag, the topic and the message
(:func:`~.reader.message_where`). It holds only the scans that images still to come need
(memory stays bounded by the stamp skew, not by the bag's length).

    >>> pairs = BagPairs("drive.mcap", "/kitti/camera_color_left/image_raw", "/kitti/velo/pointcloud")  # doctest: +SKIP
    >>> print(pairs.pairing.describe())                                                                # doctest: +SKIP
    >>> for p in pairs:                                                                                # doctest: +SKIP
    ...     if isinstance(p, BagPair):
    ...         sparse = project_points(p.points, p.K, p.T_cam_lidar, p.image_size)
"""

from __future__ import annotations

import os
from collections import Counter, deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from semattnet._errors import DataError, InputError
from semattnet._utils.bounds import MAX_SKEW_S
from semattnet.geometry import RigCalibration, read_rig_json

from .decode import (
    MAX_POINT_COORDINATE_M,
    CameraInfoData,
    decode_camera_info,
    decode_compressed_image,
    decode_image,
    decode_pointcloud2,
    header_stamp_frame,
)
from .pairing import StampPairing, pair_stamps
from .reader import TF_STATIC_TOPIC, message_errors, message_where, open_bag, read_transforms, topic_connections

__all__ = [
    "CAMERA_INFO_TYPE",
    "IMAGE_TYPES",
    "POINTS_TYPE",
    "BagFailure",
    "BagPair",
    "BagPairs",
    "decode_message",
    "rig_camera_info",
]

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
POINTS_TYPE = "sensor_msgs/msg/PointCloud2"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"


@dataclass(frozen=True)
class BagPair:
    """One image with its nearest scan.

    Attributes:
        name: the image's index in its topic, 10 digits ("0000000003"). index: that index.
        stamp_ns: the image's header stamp (ns); scan_stamp_ns: the scan's.
        image: (H, W, 3) uint8 RGB. points: (N, 3|4) LiDAR-frame metres (+ intensity), NaN points dropped.
        frame_id: the camera (optical) frame; lidar_frame_id: the scan's frame.
        K: (3, 3) intrinsics, pixels. image_size: (width, height). T_cam_lidar: (4, 4) LiDAR -> camera.
        camera_info: the CameraInfo to write back with outputs (made from the rig when the bag has none).
        scan_index: the scan's index in the points topic. dropped_points: the scan's points with a NaN or infinite
            coordinate (dropped: the ROS mark of a beam without a return).
    """

    name: str
    index: int
    stamp_ns: int
    scan_stamp_ns: int
    image: np.ndarray
    points: np.ndarray
    frame_id: str
    lidar_frame_id: str
    K: np.ndarray
    image_size: tuple[int, int]
    T_cam_lidar: np.ndarray
    camera_info: CameraInfoData
    scan_index: int = -1
    dropped_points: int = 0

    @property
    def calibration(self) -> RigCalibration:
        """The pair's calibration as :class:`semattnet.geometry.RigCalibration` (for ``project_scan``)."""
        return RigCalibration(self.K, self.T_cam_lidar, self.image_size, self.frame_id or None, source=self.name)


@dataclass(frozen=True)
class BagFailure:
    """An image of the bag that gives no pair: its ``name`` and ``index`` (as :class:`BagPair`'s) and ``error``,
    the one-line :class:`DataError` naming the bag, the topic, the message index and what is wrong."""

    name: str
    index: int
    error: DataError


_T = TypeVar("_T")
#: A decoded scan: points, stamp (ns), LiDAR frame, points dropped (NaN / infinite).
_Scan = tuple[np.ndarray, int, str, int]


def decode_message(where: str, decode: Callable[[], _T]) -> _T | DataError:
    """``decode()``, or the :class:`DataError` it raised (a message rosbags cannot deserialise becomes one
    naming ``where``), returned rather than raised so that one bad message fails only its own frames."""
    try:
        with message_errors(where):
            return decode()
    except DataError as exc:
        return exc


def rig_camera_info(rig: RigCalibration, frame_id: str = "", stamp: int = 0) -> CameraInfoData:
    """A distortion-free CameraInfo of a rig (``P = [K | 0]``)."""
    if rig.image_size is None:
        raise DataError(f"{rig.source or 'rig'}: the calibration does not give the image size")
    K = np.asarray(rig.K, dtype=np.float64)
    w, h = rig.image_size
    return CameraInfoData(
        w, h, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]), "plumb_bob", frame_id, stamp
    )


def _skew_ns(max_skew: float) -> int:
    """``max_skew`` seconds as nanoseconds, when finite and in [0, :data:`~semattnet._utils.bounds.MAX_SKEW_S`]."""
    if isinstance(max_skew, bool) or not isinstance(max_skew, int | float) or not 0 <= max_skew <= MAX_SKEW_S:
        raise InputError(f"max_skew: must be a number of seconds in 0..{MAX_SKEW_S:g}, got {max_skew!r}")
    return round(max_skew * 1e9)


class BagPairs:
    """Image/scan pairs of one bag (see the module doc).

    Args:
        path: a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.
        image_topic: ``sensor_msgs/Image`` (:data:`~.decode.IMAGE_ENCODINGS`) or ``sensor_msgs/CompressedImage``.
        points_topic: ``sensor_msgs/PointCloud2`` with x, y, z.
        camera_info_topic: ``sensor_msgs/CameraInfo``; None: the bag's only CameraInfo topic (or the one sharing
            the image topic's namespace). Not needed with ``rig``.
        rig: a rig file (:func:`semattnet.geometry.read_rig_json`) or a ``RigCalibration`` (e.g. from
            :func:`semattnet.geometry.load_rig`); overrides the bag's CameraInfo intrinsics and ``/tf_static``.
        max_skew: seconds between an image and its scan at most (None: half the scan period).
        rectified: the images are rectified: intrinsics are CameraInfo's ``P[:, :3]`` (else its ``K``).
        tf_topic: where the static transforms are.

    Iterating yields one :class:`BagPair` or :class:`BagFailure` per image of ``image_topic``, in order (module
    doc); ``len`` is the number of images.

    Raises:
        DataError: at construction, what is wrong with the whole bag: a missing topic or wrong type, a topic
            without messages, no scan within ``max_skew`` of any image, a bad ``/tf_static`` transform (NaN,
            infinite, a quaternion off unit length), no chain or two disagreeing chains between the LiDAR and camera
            frames, no CameraInfo or none usable; naming the file, topic and message. While iterating: a truncated
            or corrupt bag (the pass ends); a bad message (a CameraInfo one too) is a :class:`BagFailure` of the
            images that need it, not an exception.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        image_topic: str,
        points_topic: str,
        camera_info_topic: str | None = None,
        rig: str | os.PathLike[str] | RigCalibration | None = None,
        max_skew: float | None = None,
        rectified: bool = True,
        tf_topic: str = TF_STATIC_TOPIC,
    ) -> None:
        skew = None if max_skew is None else _skew_ns(max_skew)  # a bad tolerance: before the bag is opened
        self.path, self.image_topic, self.points_topic = Path(path), image_topic, points_topic
        self.rig = read_rig_json(rig) if isinstance(rig, (str, os.PathLike)) else rig
        self.rectified = rectified
        self._transforms: dict[tuple[str, str], np.ndarray] = {}
        with open_bag(self.path) as reader:
            self.camera_info_topic = camera_info_topic
            if self.rig is None and camera_info_topic is None:
                self.camera_info_topic = self._find_camera_info(reader)
            self._scan_headers(reader)
            self.tree = read_transforms(reader, self.path, tf_topic) if self.rig is None else None
        self.pairing: StampPairing = pair_stamps(self.image_stamps, self.scan_stamps, skew)
        self._check_pairing()
        self._check_calibration()

    def _check_calibration(self) -> None:
        """Every calibration question answered up front: ``/tf_static`` (a missing, conflicting or absurd chain)
        fails the run; a bad CameraInfo message fails the images nearest to it, or the run when it leaves no
        paired image a usable one (one line naming that message, not a skip line per image)."""
        bad: list[DataError] = []
        paired = [int(i) for i in np.nonzero(self.pairing.match >= 0)[0]]
        for i in paired:
            near = self._nearest_info(i)
            if isinstance(near, DataError):
                bad.append(near)
                continue
            self.T_cam_lidar(self._camera_frame(i), self.scan_frames[self.pairing.match[i]])
            self._camera_info(i)
        if bad and len(bad) == len(paired):
            raise DataError(f"{self.path}: {bad[0]}; no image has a usable CameraInfo")

    def _find_camera_info(self, reader: Any) -> str:
        topics: list[str] = sorted({c.topic for c in reader.connections if c.msgtype == CAMERA_INFO_TYPE})
        if not topics:
            raise DataError(
                f"{self.path}: no sensor_msgs/CameraInfo topic for {self.image_topic!r}; "
                "give the camera-info topic or a rig file"
            )
        if len(topics) == 1:
            return topics[0]
        ns = self.image_topic.rsplit("/", 1)[0]
        near = [t for t in topics if t.rsplit("/", 1)[0] == ns]
        if len(near) == 1:
            return near[0]
        raise DataError(f"{self.path}: several CameraInfo topics ({', '.join(topics)}); say which one")

    def _scan_headers(self, reader: Any) -> None:
        """Pass 1: stamps and frame ids of images and scans (headers only), every CameraInfo decoded."""
        ros1 = not reader.is2
        image_conns = topic_connections(reader, self.image_topic, IMAGE_TYPES, self.path)
        scan_conns = topic_connections(reader, self.points_topic, (POINTS_TYPE,), self.path)
        info_conns = []
        if self.camera_info_topic is not None:
            info_conns = topic_connections(reader, self.camera_info_topic, (CAMERA_INFO_TYPE,), self.path)
        heads: dict[str, list[tuple[int, str]]] = {self.image_topic: [], self.points_topic: [], "": []}
        self.infos: list[CameraInfoData | DataError] = []  # a bad one fails the images nearest to it
        for conn, t, raw in reader.messages(connections=image_conns + scan_conns + info_conns):
            key = "" if conn.topic == self.camera_info_topic else conn.topic  # "": the CameraInfo messages
            noun = "image" if conn.topic == self.image_topic else "message"
            with message_errors(message_where(conn.topic, len(heads[key]), self.path, noun)):
                stamp, frame = header_stamp_frame(raw, ros1)
            if not key:
                self.infos.append(self._decode_info(reader, conn, raw, len(self.infos)))
            heads[key].append((stamp or t, frame))
        self.image_stamps = np.array([s for s, _ in heads[self.image_topic]], dtype=np.int64)
        self.image_frames = [f for _, f in heads[self.image_topic]]
        self.scan_stamps = np.array([s for s, _ in heads[self.points_topic]], dtype=np.int64)
        self.scan_frames = [f for _, f in heads[self.points_topic]]
        if self.camera_info_topic is not None and not self.infos:
            raise DataError(f"{self.path}: topic {self.camera_info_topic!r} has no message")
        self._info_stamps = np.array([s for s, _ in heads[""]], dtype=np.int64)

    def _decode_info(self, reader: Any, conn: Any, raw: Any, k: int) -> CameraInfoData | DataError:
        where = message_where(conn.topic, k)  # the image that needs it names the bag

        def decode() -> CameraInfoData:
            return decode_camera_info(reader.deserialize(raw, conn.msgtype), where)

        return decode_message(where, decode)

    def _check_pairing(self) -> None:
        for topic, stamps in ((self.image_topic, self.image_stamps), (self.points_topic, self.scan_stamps)):
            if len(stamps) == 0:
                raise DataError(f"{self.path}: topic {topic!r} has no message")
        p = self.pairing
        if p.paired == 0:
            raise DataError(
                f"{self.path}: no {self.points_topic} scan within {p.max_skew_ns / 1e6:.1f} ms of any "
                f"{self.image_topic} image ({len(self.image_stamps)} images, {p.n_scans} scans, nearest "
                f"{p.skew_ns.min() / 1e6:.1f} ms apart); raise the max skew"
            )

    def _camera_frame(self, i: int) -> str:
        if self.image_frames[i]:
            return self.image_frames[i]
        return self._camera_info(i).frame_id

    def _frame_where(self, i: int) -> str:
        """The start of every error of image ``i``: ``BAG: IMAGE_TOPIC image I``."""
        return message_where(self.image_topic, i, self.path, "image")

    def _nearest_index(self, i: int) -> int:
        """The index of the CameraInfo message nearest in time to image ``i`` (there must be one)."""
        return int(np.argmin(np.abs(self._info_stamps - self.image_stamps[i])))

    def _nearest_info(self, i: int) -> CameraInfoData | DataError | None:
        """The bag's CameraInfo nearest in time to image ``i`` (or its error), None without a CameraInfo topic."""
        return self.infos[self._nearest_index(i)] if self.infos else None

    def _camera_info(self, i: int) -> CameraInfoData:
        """The CameraInfo nearest in time to image ``i`` (from the rig when given).

        Raises:
            DataError: that CameraInfo message is bad: ``BAG: IMAGE_TOPIC image I: INFO_TOPIC message K: WHY``.
        """
        near = self._nearest_info(i)
        if isinstance(near, DataError):
            raise DataError(f"{self._frame_where(i)}: {near}")
        if self.rig is not None:
            info = rig_camera_info(self.rig, self.image_frames[i], int(self.image_stamps[i]))
            if near is not None:  # keep the bag's own message for the sink, with the rig's intrinsics
                info = CameraInfoData(
                    info.width,
                    info.height,
                    info.K,
                    near.D,
                    near.R,
                    info.P,
                    near.distortion_model,
                    near.frame_id,
                    near.stamp_ns,
                )
            return info
        assert near is not None  # without a rig the CameraInfo topic is found or given, and has messages
        return near

    def T_cam_lidar(self, camera_frame: str, lidar_frame: str) -> np.ndarray:
        """(4, 4) LiDAR -> camera: the rig's, else chained from ``/tf_static`` (cached per frame pair)."""
        if self.rig is not None:
            return np.asarray(self.rig.T_cam_lidar, dtype=np.float64)
        key = (camera_frame, lidar_frame)
        if key not in self._transforms:
            assert self.tree is not None
            T = self.tree.lookup(camera_frame, lidar_frame)
            metres = float(np.linalg.norm(T[:3, 3]))
            if metres > MAX_POINT_COORDINATE_M:
                raise DataError(
                    f"{self.tree.source}: the LiDAR frame {lidar_frame!r} is {metres:.3g} m from the "
                    f"camera frame {camera_frame!r}; a camera and a LiDAR of one rig are metres "
                    "apart"
                )
            self._transforms[key] = T
        return self._transforms[key]

    def __len__(self) -> int:
        return len(self.image_stamps)

    def no_scan_error(self, i: int) -> DataError:
        """The error of image ``i`` that has no scan within the max skew."""
        p = self.pairing
        return DataError(
            f"{self._frame_where(i)}: no {self.points_topic} scan within "
            f"{p.max_skew_ns / 1e6:.1f} ms (nearest {p.skew_ns[i] / 1e6:.1f} ms apart)"
        )

    def _decode_image(self, reader: Any, conn: Any, raw: Any, i: int) -> np.ndarray | DataError:
        where = message_where(conn.topic, i, self.path, "image")

        def decode() -> np.ndarray:
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == IMAGE_TYPES[1]:
                return decode_compressed_image(msg, where)
            return decode_image(msg, where)

        return decode_message(where, decode)

    def _decode_scan(self, reader: Any, conn: Any, raw: Any, j: int) -> _Scan | DataError:
        where = message_where(conn.topic, j)  # the image that needs it names the bag

        def decode() -> _Scan:
            msg = reader.deserialize(raw, conn.msgtype)
            pts = decode_pointcloud2(msg, where)
            dropped = int(msg.height) * int(msg.width) - len(pts)  # the NaN / infinite points
            return pts, int(self.scan_stamps[j]), str(msg.header.frame_id).lstrip("/"), dropped

        return decode_message(where, decode)

    def _pair(self, i: int, image: np.ndarray, scan: _Scan) -> BagPair:
        points, scan_stamp, lidar_frame, dropped = scan
        info = self._camera_info(i)
        frame = self._camera_frame(i)
        size = self.rig.image_size if self.rig is not None else info.image_size
        assert size is not None
        if image.shape[:2] != (size[1], size[0]):
            said = "the rig"
            if self.rig is None:
                said = message_where(str(self.camera_info_topic), self._nearest_index(i))
            raise DataError(
                f"{self._frame_where(i)} is {image.shape[1]}x{image.shape[0]}, the calibration ({said}) "
                f"says {size[0]}x{size[1]}"
            )
        K = np.asarray(self.rig.K, dtype=np.float64) if self.rig is not None else info.intrinsics(self.rectified)
        return BagPair(
            f"{i:010d}",
            i,
            int(self.image_stamps[i]),
            scan_stamp,
            image,
            points,
            frame,
            lidar_frame,
            K,
            (int(size[0]), int(size[1])),
            self.T_cam_lidar(frame, lidar_frame),
            info,
            int(self.pairing.match[i]),
            dropped,
        )

    def _outcome(
        self, i: int, image: np.ndarray | DataError | None, scans: dict[int, _Scan | DataError]
    ) -> BagPair | BagFailure:
        """Image ``i``'s pair, or its failure: no scan near enough, a bad image, a bad scan, a wrong size."""
        j = int(self.pairing.match[i])
        scan = scans.get(j) if j >= 0 else None
        if image is None or scan is None:
            return BagFailure(f"{i:010d}", i, self.no_scan_error(i))
        if isinstance(image, DataError):
            return BagFailure(f"{i:010d}", i, image)
        if isinstance(scan, DataError):
            return BagFailure(f"{i:010d}", i, DataError(f"{self._frame_where(i)}: {scan}"))
        try:
            return self._pair(i, image, scan)
        except DataError as exc:
            return BagFailure(f"{i:010d}", i, exc)

    def __iter__(self) -> Iterator[BagPair | BagFailure]:
        """Pass 2: decode images and the scans they need; yield every image's outcome in image order."""
        match = self.pairing.match
        need = Counter(int(j) for j in match if j >= 0)
        scans: dict[int, _Scan | DataError] = {}
        pending: deque[tuple[int, np.ndarray | DataError | None]] = deque()
        n_img = n_scan = 0
        with open_bag(self.path) as reader:
            conns = [c for c in reader.connections if c.topic in (self.image_topic, self.points_topic)]
            for conn, _, raw in reader.messages(connections=conns):
                if conn.topic == self.points_topic:
                    j, n_scan = n_scan, n_scan + 1
                    if need[j]:
                        scans[j] = self._decode_scan(reader, conn, raw, j)
                else:
                    i, n_img = n_img, n_img + 1
                    pending.append((i, self._decode_image(reader, conn, raw, i) if match[i] >= 0 else None))
                while pending and (match[pending[0][0]] < 0 or int(match[pending[0][0]]) in scans):
                    i, image = pending.popleft()
                    yield self._outcome(i, image, scans)
                    j = int(match[i])
                    if j >= 0:
                        need[j] -= 1
                        if need[j] == 0:
                            del scans[j]
