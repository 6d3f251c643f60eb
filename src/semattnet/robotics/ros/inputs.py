"""What a live node receives, kept raw and paired: the newest image with its scan, by header stamp.

Messages arrive on the transport's threads, deserialised. :class:`PairingInputs` keeps each image and scan as it
came (:class:`Stamped`: its header stamp and frame id, the message not decoded) and pairs images with scans by the
bag's rule (:func:`~semattnet.robotics.bags.pairing.pair_stamps`: the nearest scan within the max skew, default half
the scan period). An image is decided once a scan at or after its stamp has arrived, or a newer image has (images
and scans arrive in stamp order, so the nearest scan is known then), or at once when the newest scan precedes it
within the max skew and, by the scan period estimated from the recent scans, the next scan cannot be nearer
(``image - last <= last + period - image``: a LiDAR stamped just before the camera is not waited a period for).
Only the newest decided image is kept (older undecided ones are lost before pairing, counted), and the pair goes
to a single slot. Images and scans are decoded only for the pair the worker takes (:meth:`Stamped.decode`), so a
pair that goes stale costs its deserialisation only; CameraInfo and transforms are decoded as they come (a bad one
is one logged line naming the topic and the message, then forgotten).

Transforms: ``/tf_static`` into a :class:`~semattnet.robotics.bags.tf.TransformTree`; ``/tf``, the newest
transform per child frame (bounded memory), over the static ones (:meth:`PairingInputs.lookup`).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
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
from semattnet.robotics.bags.pairing import estimate_period_ns, pair_stamps
from semattnet.robotics.bags.tf import TransformTree, checked_transform

from .status import TopicCounts

__all__ = ["Counts", "Pair", "PairingInputs", "Stamped", "decode_sparse_depth"]

log = logging.getLogger("semattnet.ros")

#: Images and scans kept while waiting to be paired (a second at 10 Hz is far more than a skew needs).
KEEP = 8
#: Child frames whose newest ``/tf`` transform is kept, at most (a robot has tens).
MAX_TF_FRAMES = 1000
#: The input roles counted.
ROLES = ("image", "scan", "camera_info", "tf_static", "tf")


@dataclass(frozen=True)
class Stamped:
    """One input as it came: header stamp (ns), frame id, the deserialised message (not decoded), ``where`` (topic
    and message, for errors) and the decoder of its kind (:meth:`decode`)."""

    stamp_ns: int
    frame_id: str
    message: object
    where: str
    decoder: Callable[[object, str], np.ndarray]

    def decode(self) -> np.ndarray:
        """The message decoded (an image's (H, W, 3) uint8 RGB, a scan's points or sparse depth).

        Raises:
            DataError: it cannot be decoded; one line starting with ``where``.
        """
        try:
            return self.decoder(self.message, self.where)
        except (SemAttNetError, ValueError, TypeError, AttributeError, IndexError) as exc:
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise DataError(text if text.startswith(self.where) else f"{self.where}: {text}") from None


@dataclass(frozen=True)
class Pair:
    """An image and its scan (LiDAR points, or a sparse depth image), with the CameraInfo newest at pairing."""

    image: Stamped
    scan: Stamped
    camera_info: CameraInfoData | None


class Counts:
    """What happened to the inputs (totals since the start): per role (``image``, ``scan``, ``camera_info``,
    ``tf_static``, ``tf``) a :class:`~.status.TopicCounts`, and the pairs made."""

    def __init__(self) -> None:
        self.topics = {role: TopicCounts() for role in ROLES}
        self.paired = 0

    @property
    def received(self) -> dict[str, int]:
        """Messages received by role."""
        return {role: c.received for role, c in self.topics.items() if c.received}

    @property
    def bad(self) -> int:
        """Messages refused, all roles."""
        return sum(c.bad for c in self.topics.values())

    @property
    def unpaired(self) -> int:
        """Images lost before pairing (overtaken before a scan came, or none within the max skew)."""
        return self.topics["image"].lost


def decode_sparse_depth(msg: ImageMsg, topic: str) -> np.ndarray:
    """(H, W) float32 metres (0 = none) of a sparse depth ``sensor_msgs/Image``: ``32FC1`` metres or ``16UC1``
    millimetres (NaN, infinite, <= 0: no depth).

    Raises:
        DataError: another encoding, other than the bytes the header says, or rows twice as long as the encoding
            makes them (e.g. ``32FC1`` data sent as ``16UC1``); naming the topic.
    """
    enc = str(msg.encoding).upper()
    kinds = {"32FC1": ("f4", 1.0), "16UC1": ("u2", 0.001)}
    if enc not in kinds:
        raise DataError(f"{topic}: unsupported sparse depth encoding {msg.encoding!r} (semattnet reads 32FC1, 16UC1)")
    kind, scale = kinds[enc]
    dtype = np.dtype((">" if msg.is_bigendian else "<") + kind)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    row = w * dtype.itemsize
    if step < row or data.size != h * step:
        raise DataError(f"{topic}: sparse depth holds {data.size} bytes, {h} rows of {step} make {h * step}")
    if step - row >= max(64, row):  # row padding as long as the row: the pixels are not the encoding's size
        raise DataError(
            f"{topic}: {msg.encoding} rows of {w} pixels take {row} bytes, the message's rows {step}: "
            "its data is not of that encoding"
        )
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


def _image_decoder(compressed: bool) -> Callable[[object, str], np.ndarray]:
    if compressed:
        return lambda msg, where: decode_compressed_image(cast(CompressedImageMsg, msg), where)
    return lambda msg, where: decode_image(cast(ImageMsg, msg), where)


def _scan_decoder(sparse: bool) -> Callable[[object, str], np.ndarray]:
    if sparse:
        return lambda msg, where: decode_sparse_depth(cast(ImageMsg, msg), where)
    return lambda msg, where: decode_pointcloud2(cast(PointCloud2Msg, msg), where)


class PairingInputs:
    """The node's inputs (module doc). ``on_pair`` is called (from a transport thread) with each new pair.

    Args:
        topics: ``{"image", "scan", "camera_info", "tf_static", "tf"}`` resolved names (the errors name them).
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
        self._dynamic: dict[str, tuple[int, str, np.ndarray]] = {}  # child -> (stamp, parent, T_parent_child)
        self._images: deque[Stamped] = deque()
        self._scans: deque[Stamped] = deque()
        self._used: set[int] = set()  # ids of the scans in the buffer that were paired
        self._decoders = {"image": _image_decoder(compressed), "scan": _scan_decoder(sparse)}
        self._lock = threading.Lock()

    def _where(self, role: str) -> str:
        """Count a message of ``role`` received; ``TOPIC message N`` (N from 0 per topic)."""
        c = self.counts.topics[role]
        c.received += 1
        return f"{self.topics.get(role, role)} message {c.received - 1}"

    def _decoded(self, role: str, msg: _M, decode: Callable[[_M, str], _T]) -> tuple[_T, str] | None:
        """``decode(msg, where)`` and ``where``; a failure is one logged line and None (the message is forgotten)."""
        with self._lock:  # the transport may call from several threads
            where = self._where(role)
        try:
            got = decode(msg, where), where
        except (SemAttNetError, ValueError, TypeError, AttributeError, IndexError) as exc:
            with self._lock:
                self.counts.topics[role].bad += 1
            log.warning("%s", exc if str(exc).startswith(where) else f"{where}: {exc}")
            return None
        with self._lock:
            self.counts.topics[role].decoded += 1
        return got

    def _keep(self, role: str, msg: object) -> None:
        """An image or scan kept as it came (not decoded), then pairing tried."""
        head = cast(_Headed, msg).header
        with self._lock:
            where = self._where(role)
            item = Stamped(msg_stamp_ns(head.stamp), str(head.frame_id).lstrip("/"), msg, where, self._decoders[role])
            buffer = self._images if role == "image" else self._scans
            if len(buffer) >= KEEP:
                self._evict(role, buffer.popleft())
            buffer.append(item)
            self._match()

    def _evict(self, role: str, item: Stamped) -> None:
        """An image or scan pushed out of a full buffer: lost before pairing (a scan only if never paired)."""
        if role == "image" or id(item) not in self._used:
            self.counts.topics[role].lost += 1
        self._used.discard(id(item))

    def note_decoded(self, role: str) -> None:
        """An image or scan of a pair taken by the worker was decoded."""
        with self._lock:
            self.counts.topics[role].decoded += 1

    def note_bad(self, role: str) -> None:
        """An image or scan of a pair taken by the worker could not be decoded."""
        with self._lock:
            self.counts.topics[role].bad += 1

    @property
    def waiting(self) -> int:
        """Images waiting to be paired."""
        with self._lock:
            return len(self._images)

    def on_image(self, msg: object) -> None:
        """A ``sensor_msgs/Image`` (rgb8, bgr8, mono8, ...) or ``CompressedImage`` (the transport deserialised the
        topic's type), kept raw."""
        self._keep("image", msg)

    def on_scan(self, msg: object) -> None:
        """A ``sensor_msgs/PointCloud2`` (x, y, z), or a sparse depth ``Image`` with ``sparse``, kept raw."""
        self._keep("scan", msg)

    def on_camera_info(self, msg: object) -> None:
        """A ``sensor_msgs/CameraInfo``: the newest good one is used."""
        got = self._decoded("camera_info", cast(CameraInfoMsg, msg), decode_camera_info)
        if got is not None:
            self.camera_info = got[0]

    def on_tf_static(self, msg: object) -> None:
        """A ``tf2_msgs/TFMessage`` of static transforms."""
        self._decoded("tf_static", cast(TFMessageMsg, msg), self.tree.add_message)

    def on_tf(self, msg: object) -> None:
        """A ``tf2_msgs/TFMessage`` of dynamic transforms: the newest per child frame is kept."""
        self._decoded("tf", cast(TFMessageMsg, msg), self._add_dynamic)

    def _add_dynamic(self, msg: TFMessageMsg, where: str) -> None:
        checked = []
        for t in msg.transforms:
            parent, child = str(t.header.frame_id).lstrip("/"), str(t.child_frame_id).lstrip("/")
            tr, rot = t.transform.translation, t.transform.rotation
            try:
                T = checked_transform((tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w))
            except DataError as exc:
                raise DataError(f"{where}: transform {parent!r} -> {child!r}: {exc}") from None
            checked.append((child, (msg_stamp_ns(t.header.stamp), parent, T)))
        with self._lock:
            for child, edge in checked:
                old = self._dynamic.get(child)
                if old is not None and old[0] > edge[0]:
                    continue  # an older transform than the one kept
                if old is None and len(self._dynamic) >= MAX_TF_FRAMES:
                    raise DataError(f"{where}: more than {MAX_TF_FRAMES} child frames on /tf; {child!r} ignored")
                self._dynamic[child] = edge

    def lookup(self, target: str, source: str) -> np.ndarray:
        """(4, 4) ``T_target_source`` through the static transforms and the newest dynamic ones (``/tf`` over
        ``/tf_static`` where both give a child frame's parent).

        Raises:
            DataError: no chain joins the frames, or two disagree (:meth:`TransformTree.lookup`).
        """
        with self._lock:
            dynamic = dict(self._dynamic)
        if not dynamic:
            return self.tree.lookup(target, source)
        names = f"{self.tree.source} and {self.topics.get('tf', '/tf')}"
        tree = self.tree.copy(names)
        for child, (_, parent, T) in dynamic.items():
            tree.add(parent, child, T)
        return tree.lookup(target, source)

    def _skew(self, period: int) -> int:
        return period // 2 if self.max_skew_ns is None else self.max_skew_ns

    def _decided(self, images: list[Stamped], newest_scan: int) -> list[int]:
        """The indices of the images decided (module doc)."""
        last = len(images) - 1
        out = [i for i, im in enumerate(images) if im.stamp_ns <= newest_scan or i < last]
        if out and out[-1] == last:
            return out
        gap = images[last].stamp_ns - newest_scan
        if len(self._scans) > 1:
            period = estimate_period_ns(np.array([s.stamp_ns for s in self._scans]))
            if gap <= min(self._skew(period), newest_scan + period - images[last].stamp_ns):
                out.append(last)
        return out

    def _match(self) -> None:
        """Pair the newest decided image (module doc); called with the lock held."""
        if not self._images or not self._scans:
            return
        images = list(self._images)
        decided = self._decided(images, max(s.stamp_ns for s in self._scans))
        if not decided:
            return
        k = decided[-1]
        image = images[k]
        scans = list(self._scans)
        p = pair_stamps(np.array([image.stamp_ns]), np.array([s.stamp_ns for s in scans]), self.max_skew_ns)
        for _ in range(k + 1):
            self._images.popleft()
        self.counts.topics["image"].lost += k + int(p.match[0] < 0)
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
        scan = scans[int(p.match[0])]
        self._used.add(id(scan))
        self.on_pair(Pair(image, scan, self.camera_info))
