r"""The robot outputs of the frame loop (:class:`~semattnet.inference.sinks.RunSink`\ s): a ROS bag
(``--bag-out``, :class:`BagSink`) and a Rerun recording, spawned viewer or served web viewer (``--rerun``,
``--rerun-spawn``, ``--rerun-serve``, :class:`RerunSink`); the live Foxglove server is
:class:`semattnet.robotics.live.LiveSink`.

Each output is written into a hidden folder beside its target and moved into place at the end of the run
(nothing is left of a failed run; a killed run's folder is removed by the next one). A resumed run feeds
them the frames it keeps, in their place, so a resumed run's bag equals an uninterrupted run's.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.outputs import clean_stale_stages
from semattnet._utils.registry import option
from semattnet.data.frames import Frame
from semattnet.geometry.cameras import CameraInfoData
from semattnet.inference.sinks import OutputSettings, Prediction, RunSink, Sink, SinkOptions, register_sink
from semattnet.inference.uncertainty import UncertaintyLimit
from semattnet.robotics.frame import RobotFrame, pinhole_info, stamp_ns
from semattnet.robotics.gate import exposed, is_loopback, parse_address

if TYPE_CHECKING:
    from semattnet.robotics.bags import BagWriter
    from semattnet.robotics.rerun import RerunLogger

__all__ = ["BagOutOptions", "BagSink", "RerunOptions", "RerunSink", "camera_info", "stamp_ns"]


class _StagedTarget(RunSink):
    """A run output at ``target``, written into a hidden folder beside it and moved into place at commit."""

    target: Path | None
    _dir: Path | None = None  # the hidden folder, between open and commit / abort (a class default, not a field)

    def targets(self) -> list[Path]:
        return [] if self.target is None else [Path(self.target)]

    def _begin(self, overwrite: bool) -> Path:
        import tempfile

        from semattnet._utils.distributed import world_size

        if self.target is None:
            raise InputError("a staged run output needs a target path")
        if world_size() > 1:
            raise InputError(f"{self.target}: a bag or Rerun recording is written by one process (not under torchrun)")
        target = Path(self.target)
        target.parent.mkdir(parents=True, exist_ok=True)
        clean_stale_stages(target.parent, f".{target.name}.semattnet-stage.")  # what killed runs left
        self._overwrite, self._count = overwrite, 0
        self._dir = Path(tempfile.mkdtemp(prefix=f".{target.name}.semattnet-stage.{os.getpid()}.", dir=target.parent))
        return self._dir / target.name

    def _full_disk(self) -> AbstractContextManager[object]:
        """A full disk while the output is written: one line naming the target and the space."""
        from contextlib import nullcontext

        from semattnet._utils.atomic import full_disk_named

        return nullcontext() if self.target is None else full_disk_named(self.target, self._dir)

    def commit(self) -> None:
        from semattnet._utils.atomic import fsync_dir
        from semattnet._utils.outputs import refuse_existing

        assert self.target is not None and self._dir is not None  # _begin refused a missing target
        target = Path(self.target)
        try:
            refuse_existing([target], self._overwrite)
            if target.is_dir() and not target.is_symlink():
                os.replace(target, self._dir / ".replaced")
            os.replace(self._dir / target.name, target)
            fsync_dir(target.parent)
        finally:
            self.abort()

    def abort(self) -> None:
        import shutil

        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None


@dataclass(frozen=True)
class BagOutOptions(SinkOptions):
    """``--bag-out``."""

    needs_intrinsics: ClassVar[bool] = True
    clouds: ClassVar[str] = "always"
    bag_out: Path | None = option(
        "--bag-out",
        type="out-path",
        help="Also write a ROS 2 bag (MCAP; ROS 1 for .bag): depth 32FC1, coloured cloud, CameraInfo.",
    )

    def sinks(self, settings: OutputSettings) -> list[Sink]:
        if self.bag_out is None:
            return []
        s = settings
        return [
            BagSink(
                target=self.bag_out, max_depth=s.max_depth, uncertainty=s.uncertainty, max_uncertainty=s.max_uncertainty
            )
        ]


#: Where ``--rerun-serve`` without a value serves the recording (Rerun's own default port, this machine only).
RERUN_SERVE = "127.0.0.1:9876"


@dataclass(frozen=True)
class RerunOptions(SinkOptions):
    """``--rerun FILE``, ``--rerun-spawn``, ``--rerun-serve``."""

    needs_intrinsics: ClassVar[bool] = True
    clouds: ClassVar[str] = "always"
    rerun_file: Path | None = option(
        "--rerun", type="out-file", help="Also write a Rerun recording FILE.rrd.  [extra: rerun]"
    )
    rerun_spawn: bool = option(
        "--rerun-spawn", type="flag", identity=False, help="Stream the frames to a spawned Rerun viewer."
    )
    rerun_serve: str | None = option(
        "--rerun-serve",
        type="address",
        flag_value=RERUN_SERVE,
        identity=False,
        metavar="[[HOST:]PORT]",
        help=f"Serve the frames to Rerun viewers as they are completed, on [HOST:]PORT "
        f"(alone: {RERUN_SERVE}; a HOST other than this machine's also serves the web "
        "viewer).  [extra: rerun]",
    )

    def sinks(self, settings: OutputSettings) -> list[Sink]:
        if not self.asked():
            return []
        s = settings
        return [
            RerunSink(
                target=self.rerun_file,
                spawn=self.rerun_spawn,
                serve=self.rerun_serve,
                max_depth=s.max_depth,
                log=s.log,
                uncertainty=s.uncertainty,
                max_uncertainty=s.max_uncertainty,
            )
        ]


@register_sink("bag", option="--bag-out", options=BagOutOptions)
@dataclass
class BagSink(_StagedTarget):
    """``--bag-out``: a ROS 2 bag (MCAP where rosbags writes it; ROS 1 for ``.bag``) by
    :class:`semattnet.robotics.bags.BagWriter`: per frame the stored depth (the PNG's metres) as ``32FC1``
    with holes NaN, the coloured cloud and the frame's CameraInfo (``meta.camera_info``, else one made
    from ``K``), stamped with the input's header stamp and frame id (``meta``; else ``timestamp`` and
    ``camera``). ``uncertainty``: also the stored uncertainty as ``PREFIX/uncertainty`` ``32FC1`` (metres,
    NaN where none); ``max_uncertainty``: the cloud leaves out the pixels above it (the images stay whole)."""

    option: ClassVar[str] = "--bag-out"
    kind: ClassVar[str] = "bag"
    target: Path | None = Path("prediction_bag")
    fmt: str | None = None
    prefix: str = "/semattnet"
    max_depth: float | None = None
    uncertainty: bool = False
    max_uncertainty: UncertaintyLimit | None = None
    #: The open BagWriter, between open and finish.
    _writer: BagWriter | None = field(default=None, init=False, repr=False)

    def reads(self) -> frozenset[str]:
        return RobotFrame.reads(self.uncertainty, self.max_uncertainty)

    def open(self, overwrite: bool = False) -> None:
        from semattnet.robotics.bags import BagWriter

        path = self._begin(overwrite)
        with self._full_disk():
            self._writer = BagWriter(path, fmt=self.fmt, prefix=self.prefix, max_depth=self.max_depth).open()

    def write(self, stage: Path, pred: Prediction) -> None:
        if self._writer is None:
            raise InputError(f"{self.target}: the bag is not open (call open() first)")
        robot = RobotFrame.of(
            pred, self._count, self.uncertainty, self.max_depth, self.max_uncertainty, "the bag output"
        )
        with self._full_disk():
            self._writer.write_frame(robot)
        self._count += 1

    def finish(self, stage: Path) -> None:
        writer, self._writer = self._writer, None
        if writer is not None:
            with self._full_disk():
                writer.close()  # the bag is complete in the hidden folder

    def abort(self) -> None:
        writer, self._writer = self._writer, None
        try:
            if writer is not None:  # still open: BagWriter removes its stage
                writer.__exit__(RuntimeError, RuntimeError("aborted"), None)
        except Exception:  # closing a bag that failed (a full disk) fails again: the run's error stands
            pass
        finally:
            super().abort()


def _stored_uncertainty(pred: Prediction) -> np.ndarray:
    """The uncertainty as its PNG stores it (metres, 0 = none); a one-line error when the method has none."""
    u = pred.uncertainty_stored
    if u is None:
        raise InputError(f"{pred.frame.name}: --uncertainty: the method gives no per-pixel uncertainty")
    return u


def camera_info(frame: Frame) -> CameraInfoData:
    """A distortion-free CameraInfo of a frame's ``K`` and size."""
    h, w = frame.size
    return pinhole_info(np.asarray(frame.K, dtype=np.float64), w, h)


#: ``--rerun-serve``'s web viewer port (Rerun's default), served only with a HOST other than this machine.
WEB_PORT = 9090


@register_sink("rerun", option="--rerun", options=RerunOptions)
@dataclass
class RerunSink(_StagedTarget):
    """``--rerun FILE.rrd`` / ``--rerun-spawn``: per frame the camera, image, sparse input, stored depth, semantic
    map, LiDAR points and completed cloud (:class:`semattnet.robotics.rerun.RerunLogger`) at the frame's sensor time;
    ``uncertainty``: the stored uncertainty too; ``max_uncertainty``: the cloud leaves out the pixels above it."""

    option: ClassVar[str] = "--rerun"
    kind: ClassVar[str] = "rrd"
    target: Path | None = None
    spawn: bool = False
    max_depth: float | None = None
    serve: str | None = None  # ``[HOST:]PORT``: serve the frames to Rerun viewers (the URL goes to ``log``)
    log: Callable[[str], object] | None = None
    uncertainty: bool = False
    max_uncertainty: UncertaintyLimit | None = None
    #: The open RerunLogger, between open and finish.
    _logger: RerunLogger | None = field(default=None, init=False, repr=False)

    def reads(self) -> frozenset[str]:
        return RobotFrame.reads(self.uncertainty, self.max_uncertainty)

    def targets(self) -> list[Path]:
        return [] if self.target is None else [Path(self.target)]

    def open(self, overwrite: bool = False) -> None:
        from semattnet.robotics.rerun import RerunLogger

        path = self._begin(overwrite) if self.target is not None else None
        self._count = 0
        host, port, web_port = "127.0.0.1", 0, None
        if self.serve is not None:
            host, port = parse_address(self.serve, "--rerun-serve")
            web_port = None if is_loopback(host) else WEB_PORT  # rerun binds its web viewer to every interface
        with self._full_disk():
            self._logger = logger = RerunLogger(
                path,
                spawn=self.spawn,
                max_depth=self.max_depth,
                serve=self.serve is not None,
                grpc_port=port,
                web_port=web_port,
                host=host,
            )
        if self.log is not None and logger.grpc_url is not None:
            if not is_loopback(host):
                self.log(exposed("--rerun-serve", host, logger.grpc_url))
            self.log(f"Rerun stream: {logger.grpc_url} (open it with: rerun {logger.grpc_url})")
        if self.log is not None and logger.url is not None:
            self.log(f"Rerun web viewer: {logger.url}")

    def write(self, stage: Path, pred: Prediction) -> None:
        frame = pred.frame
        if frame.K is None:
            raise InputError(f"{frame.name}: the Rerun recording needs the frame's intrinsics K, none given")
        T = None if frame.calib is None else frame.calib.T_cam_lidar
        unc = _stored_uncertainty(pred) if self.uncertainty else None
        if self._logger is None:
            raise InputError("the Rerun recording is not open (call open() first)")
        with self._full_disk():
            robot = RobotFrame.of(
                pred,
                self._count,
                max_depth=self.max_depth,
                max_uncertainty=self.max_uncertainty,
                output="the Rerun recording",
            )
            self._logger.log_frame(
                stamp_ns(frame, self._count),
                frame.rgb,
                frame.K,
                np.eye(4) if T is None else T,
                sparse=frame.sparse,
                depth=pred.stored,
                semantic=frame.semantic,
                points=frame.points,
                uncertainty=unc,
                cloud=robot.cloud,
            )
        self._count += 1

    def finish(self, stage: Path) -> None:
        """The recording complete (staged); a served stream goes on until :meth:`close`."""
        with self._full_disk():
            if self._logger is not None:
                self._logger.finish_file() if self.serve is not None else self._logger.close()

    def close(self) -> None:
        """Stop serving (the run is recorded): the viewers dropped, the gRPC server stopped, within seconds."""
        if self._logger is not None:
            self._logger.close()

    def commit(self) -> None:
        if self.target is not None:
            super().commit()

    def abort(self) -> None:
        logger, self._logger = self._logger, None
        try:
            if logger is not None:
                logger.__exit__(RuntimeError, RuntimeError("aborted"), None)
        except Exception:  # a recording that failed (a full disk) fails again on close
            pass
        finally:
            super().abort()
