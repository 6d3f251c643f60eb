"""Writing bags: staged (nothing partial is left on error), ROS 1 ``.bag`` or ROS 2 (sqlite3 / MCAP).

:class:`MessageWriter` writes message objects to any of the three formats; :class:`BagWriter` is the output
sink of completed frames: per frame the completed depth as ``sensor_msgs/Image`` ``32FC1`` in metres (holes
NaN, REP 118), the coloured cloud as ``sensor_msgs/PointCloud2`` (x, y, z float32 and ``rgb`` packed as
RViz reads it) in the camera frame, the input's ``CameraInfo`` and, when given, the depth's per-pixel
uncertainty as another ``32FC1`` image in metres (``PREFIX/uncertainty``, NaN where the depth has none), all
stamped with the input image's header stamp and frame id, so ``ros2 bag play`` feeds RViz or Foxglove directly.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.atomic import fsync_dir, full_disk_named
from semattnet._utils.extras import require
from semattnet.robotics.frame import ROS_TYPES, topic_names

from .decode import CameraInfoData
from .deps import rosbags_typestore, writes_mcap

if TYPE_CHECKING:
    from semattnet.robotics.frame import RobotFrame

__all__ = ["BAG_FORMATS", "BagWriter", "MessageWriter", "bag_format", "staged_bag"]

#: Formats :class:`MessageWriter` writes.
BAG_FORMATS = ("ros1", "sqlite3", "mcap")


def bag_format(path: str | os.PathLike[str], fmt: str | None = None) -> str:
    """``fmt``, or the format ``path`` asks for: ``.bag`` -> ros1, else ROS 2 in MCAP (sqlite3 when the installed
    rosbags cannot write MCAP)."""
    if fmt is not None:
        if fmt not in BAG_FORMATS:
            raise InputError(f"bag format: expected one of {', '.join(BAG_FORMATS)}, got {fmt!r}")
        if fmt == "mcap" and not writes_mcap():
            raise InputError("bag format 'mcap': the installed rosbags cannot write MCAP (pip install -U rosbags)")
        return fmt
    if Path(path).suffix == ".bag":
        return "ros1"
    return "mcap" if writes_mcap() else "sqlite3"


@contextmanager
def staged_bag(path: str | os.PathLike[str], overwrite: bool = False) -> Iterator[Path]:
    """Yield a path in a hidden temporary folder beside ``path``; when the block succeeds it is moved to ``path``
    in one rename (a previous bag there is replaced only with ``overwrite``, and only a bag we wrote: a ROS 2
    bag folder carries :data:`~semattnet._utils.outputs.BAG_MARKER`, a ROS 1 file has it beside it), else
    removed. Stage folders of killed runs beside ``path`` are removed first.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False (checked first).
        OutputError: ``path`` exists and is not a bag we wrote.
    """
    from semattnet._utils.outputs import BAG_MARKER, Output, check_outputs, clean_stale_stages, mark_bag_file

    if Path(path).exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass --overwrite / overwrite=True)")
    check_outputs([], [Output("bag", path, "bag")], overwrite)  # only a bag of ours is replaced
    given, path = path, Path(os.path.abspath(path))  # "." has no name to stage under: its absolute path has
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_stages(path.parent, f".{path.name}.p")
    stage = Path(tempfile.mkdtemp(prefix=f".{path.name}.p{os.getpid()}.", dir=path.parent))
    try:
        with full_disk_named(given, stage):  # a full disk names the bag and the space
            yield stage / path.name
            if (stage / path.name).is_dir():
                (stage / path.name / BAG_MARKER).write_text("written by semattnet\n")
        if path.is_dir() and not path.is_symlink():
            os.replace(path, stage / ".replaced")
        os.replace(stage / path.name, path)
        if path.is_file():  # a ROS 1 bag: its mark beside it (what lets --overwrite replace it)
            mark_bag_file(path)
        fsync_dir(path.parent)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


class MessageWriter:
    """Message objects -> a new bag at ``path`` (which must not exist) in ``fmt`` (see :data:`BAG_FORMATS`).

    Connections are added on first use of a topic; ``write`` serialises with the matching type store.
    """

    def __init__(self, path: str | os.PathLike[str], fmt: str) -> None:
        self.path, self.fmt = Path(path), bag_format(path, fmt)
        self.ros1 = self.fmt == "ros1"
        self.ts = rosbags_typestore(self.ros1)
        self.counts: dict[str, int] = {}
        self._conns: dict[str, object] = {}  # rosbags connections, by topic (handed back to the writer)
        if self.ros1:
            self._writer = require("rosbags.rosbag1", "writing ROS bags").Writer(self.path)
        else:
            rosbag2 = require("rosbags.rosbag2", "writing ROS bags")
            plugin = rosbag2.StoragePlugin.MCAP if self.fmt == "mcap" else rosbag2.StoragePlugin.SQLITE3
            self._writer = rosbag2.Writer(self.path, version=rosbag2.Writer.VERSION_LATEST, storage_plugin=plugin)

    def __enter__(self) -> MessageWriter:
        self._writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self._writer.close()

    def write(self, topic: str, stamp_ns: int, msg: Any) -> None:
        """Write ``msg`` on ``topic`` received at ``stamp_ns``."""
        msgtype = msg.__msgtype__
        if topic not in self._conns:
            extra = {"latching": 1} if self.ros1 and topic == "/tf_static" else {}
            self._conns[topic] = self._writer.add_connection(topic, msgtype, typestore=self.ts, **extra)
        data = self.ts.serialize_ros1(msg, msgtype) if self.ros1 else self.ts.serialize_cdr(msg, msgtype)
        self._writer.write(self._conns[topic], int(stamp_ns), data)
        self.counts[topic] = self.counts.get(topic, 0) + 1


class BagWriter:
    """Completed frames -> a ROS 2 bag (MCAP where rosbags writes it, else sqlite3; or ``fmt``), staged and moved
    into place at :meth:`close`; on an error inside the ``with`` block nothing is left.

    Args:
        path: the bag to create (a ROS 2 bag is a folder; ``.bag`` or ``fmt="ros1"`` writes ROS 1).
        overwrite: replace an existing ``path`` (else :class:`FileExistsError` before anything is written).
        prefix: topics are ``PREFIX/depth_image`` (Image 32FC1), ``PREFIX/point_cloud`` (PointCloud2 x, y, z, rgb),
            ``PREFIX/camera_info`` and, for frames written with an uncertainty, ``PREFIX/uncertainty`` (Image 32FC1)
            (:data:`semattnet.robotics.frame.TOPICS`).
        max_depth: cloud points deeper than this are left out (None: all), metres.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        overwrite: bool = False,
        fmt: str | None = None,
        prefix: str = "/semattnet",
        max_depth: float | None = None,
    ) -> None:
        self.path, self.fmt = Path(path), bag_format(path, fmt)
        self.topics = topic_names(prefix, tuple(ROS_TYPES))
        self.max_depth = max_depth
        from semattnet._utils.outputs import Output, check_outputs

        if self.path.exists() and not overwrite:  # at once, before any frame is computed
            raise FileExistsError(f"{self.path} exists; refusing to overwrite (pass --overwrite / overwrite=True)")
        check_outputs([], [Output("bag", self.path, "bag")], overwrite)  # only a bag of ours is replaced
        self._stage = staged_bag(self.path, overwrite)
        self._out: MessageWriter | None = None
        self.frames = 0

    def __enter__(self) -> BagWriter:
        tmp = self._stage.__enter__()
        try:
            self._out = MessageWriter(tmp, self.fmt).__enter__()
        except BaseException:
            self._stage.__exit__(*_current_exc())
            raise
        return self

    def open(self) -> BagWriter:
        """Start writing (what entering the ``with`` block does); finish with :meth:`close`."""
        return self.__enter__()

    def write(
        self,
        stamp_ns: int,
        frame_id: str,
        depth: np.ndarray,
        camera_info: CameraInfoData,
        rgb: np.ndarray | None = None,
        K: np.ndarray | None = None,
        uncertainty: np.ndarray | None = None,
        keep: np.ndarray | None = None,
    ) -> None:
        """One frame: ``depth`` (H, W) metres (<= 0 or NaN = hole), the input ``camera_info``, optional ``rgb``
        (H, W, 3) uint8 colours for the cloud, ``K`` the depth's intrinsics (default: ``camera_info``'s ``P``),
        ``uncertainty`` (H, W) metres (<= 0 or NaN = none) for the uncertainty topic, ``keep`` (H, W) bool: the
        pixels the cloud keeps (default all; the depth image stays whole)."""
        from semattnet.robotics.frame import RobotFrame

        self.write_frame(
            RobotFrame.build(
                stamp_ns,
                frame_id,
                depth,
                camera_info,
                rgb=rgb,
                K=K,
                uncertainty=uncertainty,
                keep=keep,
                max_depth=self.max_depth,
            )
        )

    def write_frame(self, frame: RobotFrame) -> None:
        """One :class:`~semattnet.robotics.frame.RobotFrame`: its messages, on :attr:`topics`."""
        if self._out is None:
            raise InputError(f"{self.path}: BagWriter.write outside its with-block")
        for role, msg in frame.messages(self._out.ts).items():
            self._out.write(self.topics[role], frame.stamp_ns, msg)
        self.frames += 1

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        out, self._out = self._out, None
        try:
            if out is not None:
                out.__exit__(exc_type, exc, tb)
        except BaseException:
            self._stage.__exit__(*_current_exc())
            raise
        if exc_type is None:
            self._stage.__exit__(None, None, None)
        else:
            self._stage.__exit__(exc_type, exc, tb)

    def close(self) -> None:
        """Finish the bag and move it into place (same as leaving the ``with`` block without an error)."""
        self.__exit__(None, None, None)


def _current_exc() -> tuple[type[BaseException] | None, BaseException | None, TracebackType | None]:
    import sys

    return sys.exc_info()
