"""Recorded robot data in and out: ROS 1 bags and ROS 2 bags (sqlite3, MCAP).

Reading needs no ROS installation (``rosbags``, extra ``ros``), imported on first use; a missing one is a
one-line :class:`~semattnet.MissingDependencyError` with the install hint.

- Reading: :func:`list_topics`, :class:`BagPairs` (image + nearest scan + calibration from ``CameraInfo`` and
  ``/tf_static``, or a rig file; a :class:`BagFailure` for an image without a good pair), the decoders of
  :mod:`.decode`, :class:`TransformTree`, ``/tf`` by stamp (:mod:`.tf_buffer`).
- Writing: :func:`write_kitti_bag` / :func:`write_sensor_bag` (images, scans, CameraInfo, ``/tf_static``, ``/tf``),
  :class:`BagWriter` (completed depth 32FC1, coloured cloud, CameraInfo per frame).
- Rerun: :class:`semattnet.robotics.rerun.RerunLogger`.
"""

from .decode import (
    CameraInfoData,
    decode_camera_info,
    decode_compressed_image,
    decode_image,
    decode_pointcloud2,
    header_stamp_frame,
)
from .pairing import StampPairing, pair_stamps
from .pairs import BagFailure, BagPair, BagPairs
from .reader import TopicRow, format_topics, list_topics, open_bag
from .sensor_bag import BagTopics, SensorRecord, WrittenBag, kitti_stamps_ns, write_kitti_bag, write_sensor_bag
from .tf import NoTransformError, TransformTree
from .writer import BagWriter, MessageWriter, bag_format

__all__ = [
    "BagFailure",
    "BagPair",
    "BagPairs",
    "BagTopics",
    "BagWriter",
    "CameraInfoData",
    "MessageWriter",
    "NoTransformError",
    "SensorRecord",
    "StampPairing",
    "TopicRow",
    "TransformTree",
    "WrittenBag",
    "bag_format",
    "decode_camera_info",
    "decode_compressed_image",
    "decode_image",
    "decode_pointcloud2",
    "format_topics",
    "header_stamp_frame",
    "kitti_stamps_ns",
    "list_topics",
    "open_bag",
    "pair_stamps",
    "write_kitti_bag",
    "write_sensor_bag",
]
