"""A ROS bag (ROS 1, ROS 2 sqlite3 or MCAP) as frames: images paired with scans by
:class:`~semattnet.robotics.bags.BagPairs`, each scan projected into the camera here with
:func:`semattnet.geometry.project_points` (exactly as
:class:`~semattnet.data.sources.raw_drive.RawDriveSource` projects a KITTI scan).

Every image of the image topic is a frame. One that cannot be completed (no scan within the max skew, an
undecodable image or scan, no semantic image near enough, an empty scan) is that frame's fault: its
``read``/``load``/``check`` raises its own one-line :class:`~semattnet._errors.DataError` and the frames after
it still load. A bag is read front to back: loading (or checking) frames in order reads the bag once, a bad
frame included; asking for an earlier frame reads it again from the start. :meth:`BagSource.read` (decode)
and :meth:`BagSource.assemble` (project) let :func:`semattnet.inference.feed.completions` time the two
stages apart; ``load`` is both.
"""

from __future__ import annotations

import os
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.registry import OptionError, option
from semattnet.data.frames import Frame, IndexedSource, SensorMeta, SourceInfo, View, sensor_frame
from semattnet.data.sources.registry import SourceOptions, register_source
from semattnet.geometry import RigCalibration
from semattnet.robotics.bags import BagFailure, BagPair, BagPairs, StampPairing
from semattnet.robotics.bags.reader import message_where
from semattnet.robotics.bags.tf_buffer import TransformBuffer

__all__ = ["BagOptions", "BagSource"]


@dataclass(frozen=True)
class BagOptions(SourceOptions):
    """``--bag``: a ROS 1 or ROS 2 recording of a camera and a LiDAR."""

    heading: ClassVar[str] = "Inputs: ROS bag"
    usage: ClassVar[str] = "--bag"
    selects: ClassVar[tuple[str, ...]] = ("bag",)
    accepts: ClassVar[tuple[str, ...]] = ("segment_spec",)
    recording: ClassVar[bool] = True

    bag: Path | None = option(
        "--bag",
        type="input",
        help="A ROS 1 .bag, a ROS 2 bag folder or a .db3 / .mcap file (instead of --rgb/--sparse).",
    )
    image_topic: str | None = option("--image-topic", help="sensor_msgs/Image or CompressedImage topic.")
    points_topic: str | None = option("--points-topic", help="sensor_msgs/PointCloud2 topic (x, y, z).")
    camera_info_topic: str | None = option(
        "--camera-info-topic", help="sensor_msgs/CameraInfo topic [the bag's only one]."
    )
    rig: Path | None = option(
        "--rig", type="file", help="Rig JSON (K, T_cam_lidar, image_size) overriding CameraInfo and /tf_static."
    )
    semantic_topic: str | None = option(
        "--semantic-topic", help="Colour-coded semantic images, paired with the images by stamp."
    )
    max_skew: float | None = option(
        "--max-skew", type="seconds", help="Seconds between an image and its scan at most [half the scan period]."
    )
    list_topics: bool = option("--list-topics", type="flag", identity=False, help="Print the bag's topics and exit.")

    def check(self, segment_spec: str | None) -> None:
        if not self.list_topics and None in (self.image_topic, self.points_topic):
            raise OptionError("--bag needs --image-topic and --points-topic (see --list-topics)")
        if self.semantic_topic is not None and segment_spec is not None:
            raise OptionError("give --semantic-topic or --segment, not both")

    def listing(self) -> str | None:
        from semattnet.robotics.bags import format_topics, list_topics

        assert self.bag is not None  # it chose this input
        return format_topics(list_topics(self.bag)) if self.list_topics else None

    def reads_maps(self, semantic: Path | None) -> bool:
        return self.semantic_topic is not None

    def source(self, semantic: Path | None, log: Callable[[str], None]) -> BagSource:
        assert self.bag is not None and self.image_topic is not None and self.points_topic is not None  # checked
        return BagSource(
            self.bag,
            self.image_topic,
            self.points_topic,
            self.camera_info_topic,
            self.rig,
            self.max_skew,
            self.semantic_topic,
            log=log,
        )


@register_source("bag", option="--bag", options=BagOptions)
class BagSource(IndexedSource):
    """The frames of a bag, one per image of the image topic (see :class:`~semattnet.robotics.bags.BagPairs` for
    the arguments and what is checked at construction: topics, pairing, calibration). Frames are named by the
    image's index in its topic (``0000000003``) and carry ``timestamp`` (the image's header stamp, seconds),
    ``points``, ``calib`` and ``meta`` (a :class:`~semattnet.data.frames.SensorMeta`: ``stamp_ns``, ``frame_id``,
    ``lidar_frame_id``, ``scan_stamp_ns``, ``camera_info`` (what the bag sink writes back), ``dropped_points``).

    ``semantic_topic``: colour-coded semantic images (Cityscapes palette, ``sensor_msgs/Image`` or
    ``CompressedImage``), each image taking the one with the nearest stamp within ``max_skew`` (default: half
    their period). ``log``: where the pairing report goes (one line at construction), and what :meth:`views` says
    once about ``/tf``. ``odom_frame``: the fixed frame of ``/tf`` that poses the neighbouring frames (:meth:`views`;
    None: ``odom`` when ``/tf`` has it, else the root of its tree).

    Raises:
        DataError: at construction, what :class:`BagPairs` raises (the whole bag is unusable), a semantic topic
            that is missing, empty or near no paired image. Per frame (``read``, ``load``, ``check``): that
            frame's own one line naming the bag, the topic, the message index and what is wrong; the next frames
            still read forward.
    """

    #: Outcomes (decoded frames or their errors) kept after reading, so that asking again for one of the last
    #: few frames (``check([name])`` behind a read-ahead of two frames, then ``load``) does not restart the bag.
    keep = 4

    def __init__(
        self,
        path: str | os.PathLike[str],
        image_topic: str,
        points_topic: str,
        camera_info_topic: str | None = None,
        rig: str | os.PathLike[str] | RigCalibration | None = None,
        max_skew: float | None = None,
        semantic_topic: str | None = None,
        log: Callable[[str], None] | None = None,
        odom_frame: str | None = None,
    ) -> None:
        self.path = Path(path)
        self.odom_frame = odom_frame
        self._log = log
        self._tf: TransformBuffer | DataError | None = None  # /tf, read when views are first asked for
        self._fixed: dict[str, str | None] = {}  # camera frame -> the fixed frame posing it (None: none)
        self.pairs = BagPairs(self.path, image_topic, points_topic, camera_info_topic, rig, max_skew)
        self.indices = list(range(len(self.pairs)))
        self.names = [f"{i:010d}" for i in self.indices]
        self._index = dict(zip(self.names, self.indices, strict=True))
        self.semantic_topic = semantic_topic
        self.semantic_pairing: StampPairing | None = None
        if semantic_topic is not None:
            self.semantic_pairing = self._pair_semantic(semantic_topic, max_skew)
        self._lock = threading.Lock()
        self._pairs_it: Iterator[BagPair | BagFailure] | None = None
        self._recent: deque[BagPair | BagFailure] = deque(maxlen=self.keep)
        self._broken: DataError | None = None
        self._sem_it: Iterator[tuple[int, np.ndarray | DataError]] | None = None
        self._sem_recent: deque[tuple[int, np.ndarray | DataError]] = deque(maxlen=self.keep)
        if log is not None:
            log(self.describe())

    @property
    def semantic_match(self) -> np.ndarray | None:
        """The semantic message index per image (-1: none near enough), or None without a semantic topic."""
        return None if self.semantic_pairing is None else self.semantic_pairing.match

    def describe(self) -> str:
        """The pairing report: paired, dropped images (frames that fail), unused scans (and the semantic images)."""
        text = f"{self.path}: {self.pairs.pairing.describe()}"
        if self.semantic_pairing is not None:
            p = self.semantic_pairing
            text += f"; semantic maps from {self.semantic_topic}"
            if p.dropped_images:
                text += f" ({p.dropped_images} image(s) without one within {p.max_skew_ns / 1e6:.1f} ms)"
        return text

    @property
    def info(self) -> SourceInfo:
        """No semantic palette of its own (a semantic topic's maps are Cityscapes: ``palette``), every frame's
        header stamp."""
        return SourceInfo(self.palette, stamps_ns=[int(ns) for ns in self.stamps_ns])

    @property
    def stamps_ns(self) -> np.ndarray:
        """The header stamps (ns) of the frames, in order."""
        return self.pairs.image_stamps[self.indices]

    def _pair_semantic(self, topic: str, max_skew: float | None) -> StampPairing:
        from semattnet.robotics.bags import header_stamp_frame, open_bag, pair_stamps
        from semattnet.robotics.bags.pairs import IMAGE_TYPES
        from semattnet.robotics.bags.reader import topic_connections

        with open_bag(self.path) as reader:
            conns = topic_connections(reader, topic, IMAGE_TYPES, self.path)
            stamps = [
                header_stamp_frame(raw, not reader.is2)[0] or t for _, t, raw in reader.messages(connections=conns)
            ]
        if not stamps:
            raise DataError(f"{self.path}: topic {topic!r} has no message")
        skew = None if max_skew is None else round(max_skew * 1e9)
        p = pair_stamps(self.pairs.image_stamps, np.array(stamps, dtype=np.int64), skew)
        if not np.any((p.match >= 0) & (self.pairs.pairing.match >= 0)):
            raise DataError(
                f"{self.path}: no {topic} semantic image within {p.max_skew_ns / 1e6:.1f} ms of any "
                f"{self.pairs.image_topic} image with a scan (nearest {p.skew_ns.min() / 1e6:.1f} ms "
                "apart); raise the max skew"
            )
        return p

    def _semantic_images(self) -> Iterator[tuple[int, np.ndarray | DataError]]:
        """Every semantic message in order: the image, or the DataError of one that cannot be decoded."""
        from semattnet.palette import colors_to_ids
        from semattnet.robotics.bags import decode_compressed_image, decode_image, open_bag
        from semattnet.robotics.bags.decode import EXACT_ENCODINGS
        from semattnet.robotics.bags.pairs import IMAGE_TYPES, decode_message
        from semattnet.robotics.bags.reader import topic_connections

        assert self.semantic_topic is not None
        with open_bag(self.path) as reader:
            conns = topic_connections(reader, self.semantic_topic, IMAGE_TYPES, self.path)
            for j, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
                where = message_where(conn.topic, j)  # the frame that needs it names the bag

                def decode(conn: Any = conn, raw: Any = raw, where: str = where) -> np.ndarray:
                    msg = reader.deserialize(raw, conn.msgtype)
                    if conn.msgtype == IMAGE_TYPES[1]:
                        image = decode_compressed_image(msg, where)
                    else:  # colours read exactly: no demosaicing or YUV for a semantic image
                        image = decode_image(msg, where, EXACT_ENCODINGS)
                    colors_to_ids(image, allow_unknown=True, source=where)
                    return image

                yield j, decode_message(where, decode)

    def _frame_where(self, i: int) -> str:
        return message_where(self.pairs.image_topic, i, self.path, "image")

    def _semantic(self, i: int, size: tuple[int, int]) -> np.ndarray | None:
        """The semantic image paired with image ``i`` (read forward, restarted when asked for an earlier one).

        Raises:
            DataError: none near enough, it cannot be decoded or its size is not ``size`` (the image's, width by
                height); naming the bag, image ``i`` and the message.
        """
        if self.semantic_pairing is None:
            return None
        where = self._frame_where(i)
        j = int(self.semantic_pairing.match[i])
        if j < 0:
            p = self.semantic_pairing
            raise DataError(
                f"{where}: no {self.semantic_topic} semantic image within {p.max_skew_ns / 1e6:.1f} ms "
                f"(nearest {p.skew_ns[i] / 1e6:.1f} ms apart)"
            )
        image = self._semantic_message(j)
        if isinstance(image, DataError):
            raise DataError(f"{where}: {image}")
        if (image.shape[1], image.shape[0]) != size:
            raise DataError(
                f"{where}: {message_where(str(self.semantic_topic), j)}: the semantic image is "
                f"{image.shape[1]}x{image.shape[0]}, the image {size[0]}x{size[1]}"
            )
        return image

    def _semantic_message(self, j: int) -> np.ndarray | DataError:
        """Semantic message ``j``: one of the last few read, else read forward (from the start for an earlier)."""
        hit = [image for k, image in self._sem_recent if k == j]
        if hit:
            return hit[0]
        if self._sem_it is None or (self._sem_recent and self._sem_recent[-1][0] > j):
            self._sem_it = self._semantic_images()
            self._sem_recent.clear()
        found = next(((k, image) for k, image in self._sem_it if k == j), None)
        if found is None:
            self._sem_it = None
            raise DataError(f"{message_where(str(self.semantic_topic), j, self.path)} missing (truncated bag?)")
        self._sem_recent.append(found)
        return found[1]

    def _advance(self, i: int) -> BagPair | BagFailure:
        """Image ``i``'s outcome: the bag read forward by one iterator (again from the start only for an image
        before the last :attr:`keep` read), so ``check([name])`` then ``load(name)`` reads it once."""
        hit = [item for item in self._recent if item.index == i]
        if hit:
            return hit[0]
        pos = self._recent[-1].index if self._recent else -1
        if pos > i or (self._pairs_it is None and self._broken is None):
            self._pairs_it, self._broken = iter(self.pairs), None
            self._recent.clear()
        if self._broken is not None:  # the bag itself failed before image i: no point reading it again
            raise self._broken
        assert self._pairs_it is not None
        try:
            for item in self._pairs_it:
                self._recent.append(item)
                if item.index == i:
                    return item
            self._broken = DataError(f"{self.path}: {self.pairs.image_topic} ends before image {i} (truncated bag?)")
        except DataError as exc:
            self._broken = exc
        self._pairs_it = None
        raise self._broken

    def read(self, name: str) -> tuple[BagPair, np.ndarray | None]:
        """Frame ``name``'s image and scan (decoded) with its semantic image, or None.

        Raises:
            DataError: this frame's own error (module doc); the bag stays positioned for the next frames.
        """
        i = self._index[name]
        with self._lock:
            item = self._advance(i)
            if isinstance(item, BagFailure):
                raise item.error
            return item, self._semantic(i, (item.image.shape[1], item.image.shape[0]))

    def assemble(self, raw: tuple[BagPair, np.ndarray | None]) -> Frame:
        """The frame of what :meth:`read` returned: the scan projected into the image (:func:`sensor_frame`)."""
        p, semantic = raw
        where = f"{self._frame_where(p.index)}: {message_where(self.pairs.points_topic, p.scan_index)}"
        if p.dropped_points:  # named when nothing is left to project
            where += f" ({p.dropped_points} point(s) with a NaN or infinite coordinate dropped)"
        meta = SensorMeta(p.stamp_ns, p.frame_id, p.lidar_frame_id, p.scan_stamp_ns, p.camera_info, p.dropped_points)
        return sensor_frame(
            p.name,
            p.image,
            meta,
            p.calibration,
            points=p.points,
            where=where,
            semantic=semantic,
            paths={"bag": self.path},
        )

    def load(self, name: str) -> Frame:
        return self.assemble(self.read(name))

    def check(self, names: Sequence[str] | None = None) -> None:
        """Decode every image, scan and semantic image of ``names`` (default: all), in one pass; in order, one
        name at a time (``check([name])``) reads the bag forward once too. Raises the first bad frame's
        :class:`DataError` (the projection, e.g. an empty scan, is ``load``'s)."""
        for name in self.names if names is None else names:
            self.read(name)

    def views(self, name: str) -> tuple[View, ...]:
        """Frame ``name``'s other views: the previous and next images of the topic where they are paired frames of
        the same camera frame, each with ``T_view_cam = T_fixed_cam(t_view)^-1 @ T_fixed_cam(t)``: the camera's pose
        in the fixed frame (``odom_frame``) chained from ``/tf``, interpolated at each image's header stamp
        (:class:`~semattnet.robotics.bags.tf_buffer.TransformBuffer`), and ``/tf_static``. ``/tf`` is read once,
        when views are first asked for. Empty without ``/tf`` or without a chain from the fixed frame to the camera
        (said once to ``log``); a neighbour outside ``/tf``'s span is no view. Never raises for the bag's sake.
        """
        i = self._index[name]
        with self._lock:
            try:
                here = self._advance(i)
            except DataError:
                return ()
            fixed = None if isinstance(here, BagFailure) else self._fixed_frame(here.frame_id)
            if isinstance(here, BagFailure) or fixed is None:
                return ()
            T_fixed_here = self._pose(fixed, here)
            if T_fixed_here is None:
                return ()
            found = [self._neighbour(here, T_fixed_here, j, fixed) for j in (i - 1, i + 1) if 0 <= j < len(self.pairs)]
        return tuple(v for v in found if v is not None)

    def _pose(self, fixed: str, pair: BagPair) -> np.ndarray | None:
        """``T_fixed_cam`` of ``pair``'s camera at its image's stamp (None: no chain then, or two that disagree)."""
        tf = self._transforms()
        assert isinstance(tf, TransformBuffer)  # a fixed frame was found in it
        try:
            return tf.lookup(fixed, pair.frame_id, pair.stamp_ns)
        except DataError:
            return None

    def _say(self, line: str) -> None:
        if self._log is not None:
            self._log(line)

    def _transforms(self) -> TransformBuffer | DataError:
        """The bag's ``/tf`` over its ``/tf_static``, read on first call (a bag that cannot be read: its error)."""
        if self._tf is None:
            from semattnet.robotics.bags import open_bag
            from semattnet.robotics.bags.tf_buffer import read_tf_buffer

            try:
                with open_bag(self.path) as reader:
                    self._tf = read_tf_buffer(reader, self.path)
            except DataError as exc:
                self._tf = exc
            if isinstance(self._tf, TransformBuffer) and self._tf.skipped:
                bad = self._tf.skipped
                self._say(f"{len(bad)} bad /tf transform(s) left out of the neighbouring views' poses: {bad[0]}")
        return self._tf

    def _fixed_frame(self, camera_frame: str) -> str | None:
        """The ``/tf`` frame that poses ``camera_frame``, or None (no neighbouring views); said once per camera."""
        if camera_frame not in self._fixed:
            tf, fixed = self._transforms(), None
            try:
                if isinstance(tf, DataError):
                    raise tf
                fixed = tf.fixed_frame(camera_frame, self.odom_frame)
                self._say(
                    f"{self.path}: neighbouring frames as views, posed by /tf from {fixed!r} to the camera "
                    f"{camera_frame!r}"
                )
            except DataError as exc:
                self._say(f"{exc}; the frames get no neighbouring views")
            self._fixed[camera_frame] = fixed
        return self._fixed[camera_frame]

    def _neighbour(self, here: BagPair, T_fixed_here: np.ndarray, j: int, fixed: str) -> View | None:
        """Image ``j`` as a view of ``here`` (posed at ``T_fixed_here``): a paired frame of the same camera, posed at
        its stamp, or None."""
        from semattnet.geometry import invert_T

        try:
            there = self._advance(j)
            if isinstance(there, BagFailure) or there.frame_id != here.frame_id:
                return None
        except DataError:  # the bag ends early: no view
            return None
        T_fixed_there = self._pose(fixed, there)
        if T_fixed_there is None:
            return None
        return View(there.name, there.image, there.K, invert_T(T_fixed_there) @ T_fixed_here)

    def inputs(self) -> list[Path]:
        """The bag (a ROS 2 bag's folder too, when a storage file inside it was given)."""
        parent = self.path.parent
        folder = [parent] if self.path.is_file() and (parent / "metadata.yaml").is_file() else []
        return [self.path, *folder]
