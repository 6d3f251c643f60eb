"""What a live node receives, decoded and paired: the newest image with its scan, by header stamp.

Messages arrive on the transport's threads; :class:`PairingInputs` decodes each one at once (a bad one is one
logged line naming the topic and the message, then forgotten) and pairs images with scans by the bag's rule
(:func:`~semattnet.robotics.bags.pairing.pair_stamps`: the nearest scan within the max skew, default half the
scan period). An image is decided once a scan at or after its stamp has arrived, or a newer image has: images
and scans arrive in stamp order, so the nearest scan is known then. Only the newest decided image is kept
(older undecided ones are dropped and counted), and the pair goes to a single slot: a pair still waiting
there when a newer one comes is dropped and counted, never queued.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, TypeVar, cast

import numpy as np

from semattnet._errors import DataError, SemAttNetError
from semattnet.geometry.cameras import CameraInfoData
from semattnet.robotics.bags.decode import (
    decode_camera_info,
    decode_compressed_image,
    decode_image,
    decode_pointcloud2,
    msg_stamp_ns,
)
from semattnet.robotics.bags.messages import (
    CameraInfoMsg,
    CompressedImageMsg,
    HeaderMsg,
    ImageMsg,
    PointCloud2Msg,
    TFMessageMsg,
)
from semattnet.robotics.bags.pairing import pair_stamps
from semattnet.robotics.bags.tf import TransformTree

__all__ = ["Counts", "Pair", "PairingInputs", "Stamped", "decode_sparse_depth"]

log = logging.getLogger("semattnet.ros")

#: Images and scans kept while waiting to be paired (a second at 10 Hz is far more than a skew needs).
KEEP = 8


@dataclass(frozen=True)
class Stamped:
    """One decoded input: header stamp (ns), frame id, the data, and ``where`` (topic + message) for errors."""

    stamp_ns: int
    frame_id: str
    data: np.ndarray
    where: str


@dataclass(frozen=True)
class Pair:
    """An image and its scan (LiDAR points, or a sparse depth image), with the CameraInfo newest at pairing."""

    image: Stamped
    scan: Stamped
    camera_info: CameraInfoData | None


@dataclass
class Counts:
    """What happened to the inputs (totals since the start)."""

    received: dict[str, int] = field(default_factory=dict)
    bad: int = 0
    paired: int = 0
    unpaired: int = 0  # images with no scan within the max skew (or overtaken before one came)
    stale: int = 0  # pairs dropped from the slot by a newer one (the completer was busy)


def decode_sparse_depth(msg: ImageMsg, topic: str) -> np.ndarray:
    """(H, W) float32 metres (0 = none) of a sparse depth ``sensor_msgs/Image``: ``32FC1`` metres or ``16UC1``
    millimetres (NaN, infinite, <= 0: no depth).

    Raises:
        DataError: another encoding, or fewer bytes than the header says; naming the topic.
    """
    enc = str(msg.encoding).upper()
    kinds = {"32FC1": ("f4", 1.0), "16UC1": ("u2", 0.001)}
    if enc not in kinds:
        raise DataError(f"{topic}: unsupported sparse depth encoding {msg.encoding!r} (semattnet reads 32FC1, 16UC1)")
    kind, scale = kinds[enc]
    dtype = np.dtype((">" if msg.is_bigendian else "<") + kind)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    if step < w * dtype.itemsize or data.size < h * step:
        raise DataError(f"{topic}: sparse depth holds {data.size} bytes, {h} rows of {step} need {h * step}")
    rows = data[: h * step].reshape(h, step)[:, : w * dtype.itemsize]
    d = np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(np.float32) * np.float32(scale)
    depth: np.ndarray = np.where(np.isfinite(d) & (d > 0), d, np.float32(0)).astype(np.float32)
    return depth


_M = TypeVar("_M")
_T = TypeVar("_T")


class _Headed(Protocol):
    """A message that starts with a ``std_msgs/Header``."""

    @property
    def header(self) -> HeaderMsg: ...


class PairingInputs:
    """The node's inputs (module doc). ``on_pair`` is called (from a transport thread) with each new pair.

    Args:
        topics: ``{"image", "scan", "camera_info"}`` resolved names (the errors name them).
        on_pair: called with each new pair.
        compressed: the image topic is ``CompressedImage``.
        sparse: the scan topic is a sparse depth image.
        max_skew_ns: image-scan tolerance (None: half the scan period).
    """

    def __init__(
        self,
        topics: dict[str, str],
        on_pair: Callable[[Pair], None],
        compressed: bool = False,
        sparse: bool = False,
        max_skew_ns: int | None = None,
    ) -> None:
        self.topics, self.on_pair = topics, on_pair
        self.compressed, self.sparse, self.max_skew_ns = compressed, sparse, max_skew_ns
        self.counts = Counts()
        self.tree = TransformTree(topics.get("tf_static", "/tf_static"))
        self.camera_info: CameraInfoData | None = None
        self._images: deque[Stamped] = deque(maxlen=KEEP)
        self._scans: deque[Stamped] = deque(maxlen=KEEP)
        self._lock = threading.Lock()

    def _decoded(self, role: str, msg: _M, decode: Callable[[_M, str], _T]) -> tuple[_T, str] | None:
        """``decode(msg, where)`` and ``where``; a failure is one logged line and None (the message is forgotten)."""
        with self._lock:  # the transport may call from several threads
            n = self.counts.received.get(role, 0)
            self.counts.received[role] = n + 1
        where = f"{self.topics[role]} message {n}"
        try:
            return decode(msg, where), where
        except (SemAttNetError, ValueError, TypeError, AttributeError, IndexError) as exc:
            with self._lock:
                self.counts.bad += 1
            log.warning("%s", exc if str(exc).startswith(where) else f"{where}: {exc}")
            return None

    def on_image(self, msg: object) -> None:
        """A ``sensor_msgs/Image`` (rgb8, bgr8, mono8) or ``CompressedImage`` (the transport deserialised the
        topic's type: the casts below say which)."""
        if self.compressed:
            got = self._decoded("image", cast(CompressedImageMsg, msg), decode_compressed_image)
        else:
            got = self._decoded("image", cast(ImageMsg, msg), decode_image)
        if got is not None:
            head = cast(_Headed, msg).header
            with self._lock:
                self._images.append(Stamped(msg_stamp_ns(head.stamp), str(head.frame_id).lstrip("/"), got[0], got[1]))
                self._match()

    def on_scan(self, msg: object) -> None:
        """A ``sensor_msgs/PointCloud2`` (x, y, z), or a sparse depth ``Image`` with ``sparse``."""
        if self.sparse:
            got = self._decoded("scan", cast(ImageMsg, msg), decode_sparse_depth)
        else:
            got = self._decoded("scan", cast(PointCloud2Msg, msg), decode_pointcloud2)
        if got is not None:
            head = cast(_Headed, msg).header
            with self._lock:
                self._scans.append(Stamped(msg_stamp_ns(head.stamp), str(head.frame_id).lstrip("/"), got[0], got[1]))
                self._match()

    def on_camera_info(self, msg: object) -> None:
        """A ``sensor_msgs/CameraInfo``: the newest good one is used."""
        got = self._decoded("camera_info", cast(CameraInfoMsg, msg), decode_camera_info)
        if got is not None:
            self.camera_info = got[0]

    def on_tf_static(self, msg: object) -> None:
        """A ``tf2_msgs/TFMessage`` of static transforms."""
        self._decoded("tf_static", cast(TFMessageMsg, msg), self.tree.add_message)

    def _match(self) -> None:
        """Pair the newest decided image (module doc); called with the lock held."""
        if not self._images or not self._scans:
            return
        newest_scan = max(s.stamp_ns for s in self._scans)
        images = list(self._images)
        decided = [i for i, im in enumerate(images) if im.stamp_ns <= newest_scan or i < len(images) - 1]
        if not decided:
            return
        k = decided[-1]
        image = images[k]
        scans = list(self._scans)
        p = pair_stamps(np.array([image.stamp_ns]), np.array([s.stamp_ns for s in scans]), self.max_skew_ns)
        for _ in range(k + 1):
            self._images.popleft()
        self.counts.unpaired += k + int(p.match[0] < 0)
        if p.match[0] < 0:
            log.warning(
                "%s: no %s scan within %.1f ms (nearest %.1f ms apart)",
                image.where,
                self.topics["scan"],
                p.max_skew_ns / 1e6,
                p.skew_ns[0] / 1e6,
            )
            return
        self.counts.paired += 1
        self.on_pair(Pair(image, scans[int(p.match[0])], self.camera_info))
