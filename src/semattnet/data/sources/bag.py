"""A ROS bag (ROS 1, ROS 2 sqlite3 or MCAP) as frames: images paired with scans by
:class:`~semattnet.data.bags.BagPairs`, each scan projected into the camera here with
:func:`semattnet.geometry.project_points` (exactly as :class:`~.kitti_raw.RawDriveSource` projects a
KITTI scan).

A bag is read front to back: loading frames in order (what the frame loop does) reads the bag once;
asking for an earlier frame reads it again from the start. :meth:`BagSource.read` (decode) and
:meth:`BagSource.assemble` (project) let :func:`semattnet.inference.stream.completions` time the two
stages apart; ``load`` is both.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from semattnet._errors import DataError
from semattnet.data.bags import BagPair, BagPairs
from semattnet.data.frames import Frame, IndexedSource

__all__ = ["BagSource"]


class BagSource(IndexedSource):
    """The paired frames of a bag (see :class:`~semattnet.data.bags.BagPairs` for the arguments and what is
    checked at construction: topics, pairing, calibration). Frames are named by the image's index in its topic
    (``0000000003``) and carry ``timestamp`` (the image's header stamp, seconds), ``points``, ``calib`` and
    ``meta``: ``stamp_ns`` (int), ``frame_id``, ``lidar_frame_id``, ``scan_stamp_ns``, ``camera_info``
    (a :class:`~semattnet.data.bags.CameraInfoData`, what the bag sink writes back).

    ``semantic_topic``: colour-coded semantic images (Cityscapes palette, ``sensor_msgs/Image`` or
    ``CompressedImage``), each image taking the one with the nearest stamp within ``max_skew`` (default: half
    their period). ``log``: where the pairing report goes (one line at construction).

    Raises:
        DataError: what :class:`BagPairs` raises; an image without a semantic image near enough (naming the topic).
    """

    def __init__(self, path: str | os.PathLike[str], image_topic: str, points_topic: str,
                 camera_info_topic: str | None = None, rig: Any = None, max_skew: float | None = None,
                 semantic_topic: str | None = None, log: Callable[[str], None] | None = None) -> None:  # fmt: skip
        self.path = Path(path)
        self.pairs = BagPairs(self.path, image_topic, points_topic, camera_info_topic, rig, max_skew)
        self.indices = [int(i) for i in np.nonzero(self.pairs.pairing.match >= 0)[0]]
        self.names = [f"{i:010d}" for i in self.indices]
        self._index = dict(zip(self.names, self.indices, strict=True))
        self.semantic_topic = semantic_topic
        self.semantic_match: np.ndarray | None = None
        if semantic_topic is not None:
            self.semantic_match = self._pair_semantic(semantic_topic, max_skew)
        self._lock = threading.Lock()
        self._pairs_it: Iterator[BagPair] | None = None
        self._pos = -1
        self._sem_it: Iterator[tuple[int, np.ndarray]] | None = None
        self._sem_last: tuple[int, np.ndarray] | None = None
        if log is not None:
            log(self.describe())

    def describe(self) -> str:
        """The pairing report: paired, dropped images, unused scans (and the semantic images)."""
        text = f"{self.path}: {self.pairs.pairing.describe()}"
        if self.semantic_topic is not None:
            text += f"; semantic maps from {self.semantic_topic}"
        return text

    @property
    def stamps_ns(self) -> np.ndarray:
        """The header stamps (ns) of the frames, in order."""
        return self.pairs.image_stamps[self.indices]

    def _pair_semantic(self, topic: str, max_skew: float | None) -> np.ndarray:
        from semattnet.data.bags import header_stamp_frame, open_bag, pair_stamps
        from semattnet.data.bags.reader import topic_connections
        from semattnet.data.bags.source import IMAGE_TYPES

        with open_bag(self.path) as reader:
            conns = topic_connections(reader, topic, IMAGE_TYPES, self.path)
            stamps = [
                header_stamp_frame(raw, not reader.is2)[0] or t for _, t, raw in reader.messages(connections=conns)
            ]
        skew = None if max_skew is None else round(max_skew * 1e9)
        p = pair_stamps(self.pairs.image_stamps, np.array(stamps, dtype=np.int64), skew)
        missing = [i for i in self.indices if p.match[i] < 0]
        if missing:
            raise DataError(f"{self.path}: {len(missing)} image(s) have no {topic} semantic image within "
                            f"{p.max_skew_ns / 1e6:.1f} ms (first: image {missing[0]}, nearest "
                            f"{p.skew_ns[missing[0]] / 1e6:.1f} ms apart); raise the max skew")  # fmt: skip
        return p.match

    def _semantic_images(self) -> Iterator[tuple[int, np.ndarray]]:
        from semattnet.data.bags import decode_compressed_image, decode_image, open_bag
        from semattnet.data.bags.reader import topic_connections
        from semattnet.data.bags.source import IMAGE_TYPES
        from semattnet.data.palette import colors_to_ids

        assert self.semantic_topic is not None
        with open_bag(self.path) as reader:
            conns = topic_connections(reader, self.semantic_topic, IMAGE_TYPES, self.path)
            for j, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
                msg = reader.deserialize(raw, conn.msgtype)
                decode = decode_compressed_image if conn.msgtype == IMAGE_TYPES[1] else decode_image
                image = decode(msg, conn.topic)
                colors_to_ids(image, allow_unknown=True, source=f"{self.path}: {conn.topic} message {j}")
                yield j, image

    def _semantic(self, i: int) -> np.ndarray | None:
        """The semantic image paired with image ``i`` (read forward, restarted when asked for an earlier one)."""
        if self.semantic_match is None:
            return None
        j = int(self.semantic_match[i])
        if self._sem_last is not None and self._sem_last[0] == j:
            return self._sem_last[1]
        if self._sem_it is None or (self._sem_last is not None and self._sem_last[0] > j):
            self._sem_it = self._semantic_images()
        for k, image in self._sem_it:
            self._sem_last = (k, image)
            if k == j:
                return image
        raise DataError(f"{self.path}: {self.semantic_topic} message {j} missing (truncated bag?)")

    def read(self, name: str) -> tuple[BagPair, np.ndarray | None]:
        """Frame ``name``'s image and scan (decoded) with its semantic image, or None."""
        i = self._index[name]
        with self._lock:
            if self._pairs_it is None or self._pos >= i:
                self._pairs_it, self._pos = iter(self.pairs), -1
            for pair in self._pairs_it:
                self._pos = pair.index
                if pair.index == i:
                    return pair, self._semantic(i)
            self._pairs_it = None
        raise DataError(f"{self.path}: {self.pairs.image_topic} image {i} missing (truncated bag?)")

    def assemble(self, raw: tuple[BagPair, np.ndarray | None]) -> Frame:
        """The frame of what :meth:`read` returned: the scan projected into the image."""
        from semattnet.geometry import project_points

        p, semantic = raw
        where = f"{self.path}: {self.pairs.points_topic} message {p.index}"
        sparse = project_points(p.points, p.K, p.T_cam_lidar, p.image_size, name=where)
        meta = {"stamp_ns": p.stamp_ns, "frame_id": p.frame_id, "lidar_frame_id": p.lidar_frame_id,
                "scan_stamp_ns": p.scan_stamp_ns, "camera_info": p.camera_info}  # fmt: skip
        return Frame(p.name, p.image, sparse, semantic, K=p.K, timestamp=p.stamp_ns / 1e9, points=p.points,
                     calib=p.calibration, paths={"bag": self.path}, meta=meta)  # fmt: skip

    def load(self, name: str) -> Frame:
        return self.assemble(self.read(name))

    def check(self, names: Sequence[str] | None = None) -> None:
        """Decode every image, scan and semantic image of ``names`` (default: all), in one pass."""
        for name in self.names if names is None else names:
            self.read(name)

    def inputs(self) -> list[Path]:
        """The bag (a ROS 2 bag's folder too, when a storage file inside it was given)."""
        parent = self.path.parent
        folder = [parent] if self.path.is_file() and (parent / "metadata.yaml").is_file() else []
        return [self.path, *folder]
