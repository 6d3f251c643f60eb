"""A live view of completed frames: a Foxglove WebSocket server (``foxglove-sdk``, extra ``live``).

``semattnet predict ... --live [HOST:]PORT`` serves each frame as it is completed; open the Foxglove app
(desktop or https://app.foxglove.dev) and connect to ``ws://HOST:PORT``. Per frame, stamped with the
input's sensor time and frame id (as :class:`~semattnet.robotics.sinks.BagSink` stamps them):

============================  =====================  ==================================================
topic                         schema                 what
============================  =====================  ==================================================
``/semattnet/depth_image``    foxglove.RawImage      the completed depth as stored, ``32FC1`` metres, holes NaN
``/semattnet/uncertainty``    foxglove.RawImage      its per-pixel uncertainty as stored, ``32FC1`` metres,
                                                     NaN where none (when the method gives one)
``/semattnet/point_cloud``    foxglove.PointCloud    the coloured completed cloud (x, y, z float32, red,
                                                     green, blue, alpha uint8) in the camera frame, the
                                                     pixels above ``max_uncertainty`` left out
``/semattnet/camera_info``    foxglove.CameraCalib.  K, P, size, distortion (``meta.camera_info`` or ``K``)
``/semattnet/latency``        JSON                   ``{frame, stamp_ns, stages_ms: {stage: ms}}``
``/tf``                       foxglove.FrameTransf.  camera <- LiDAR (``calib.T_cam_lidar``), when known
``/input/image``              foxglove.RawImage      the input image, ``rgb8``
``/input/sparse``             foxglove.RawImage      the sparse input, ``32FC1`` metres, holes NaN
============================  =====================  ==================================================

Each sink logs into its own :class:`foxglove.Context`, so two sinks in one process never mix. A message
is built only when a client is subscribed to its channel: with no client :meth:`LiveSink.write` costs
next to nothing, and the server drops the oldest messages of a slow client (:data:`CLIENT_BACKLOG` kept; it never
blocks the loop). The clients reach the server through a :class:`~semattnet.robotics.gate.Gate` (at most
32 at once, 5 s for a handshake), so the server stops within seconds whatever they do: silent, half-open
or many.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, ClassVar, Protocol

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.extras import call_with_newer, optional, require
from semattnet._utils.registry import option
from semattnet.data.io import decode_depth
from semattnet.geometry.cameras import CameraInfoData
from semattnet.inference.sinks import OutputSettings, Prediction, RunSink, Sink, SinkOptions, register_sink
from semattnet.inference.uncertainty import UncertaintyLimit
from semattnet.robotics.frame import TOPICS as OUTPUT_TOPICS
from semattnet.robotics.frame import RobotFrame, frame_camera, stamp_ns
from semattnet.robotics.gate import Gate, exposed, is_loopback, parse_address

if TYPE_CHECKING:
    from semattnet.geometry import PointCloud

__all__ = ["LATENCY_SCHEMA", "LiveOptions", "LiveSink", "parse_address"]

#: Topics by role; ``PREFIX`` is :attr:`LiveSink.prefix` (the outputs' names: :data:`semattnet.robotics.frame.TOPICS`).
CHANNEL_TOPICS = {
    **{role: f"PREFIX/{name}" for role, name in OUTPUT_TOPICS.items()},
    "tf": "/tf",
    "rgb": "/input/image",
    "sparse": "/input/sparse",
}
#: The JSON schema of the latency channel.
LATENCY_SCHEMA = {
    "title": "semattnet.Latency",
    "type": "object",
    "properties": {
        "frame": {"type": "string"},
        "stamp_ns": {"type": "integer"},
        "stages_ms": {"type": "object", "additionalProperties": {"type": "number"}},
    },
}
#: Messages kept per client before the oldest is dropped (a few frames of every channel).
CLIENT_BACKLOG = 64


def _foxglove() -> ModuleType:
    """``foxglove``, or a one-line :class:`MissingDependencyError` with the install hint."""
    require("foxglove.channels", "--live")
    return require("foxglove", "--live")


def _messages() -> ModuleType:
    """The message classes: ``foxglove.messages`` (``foxglove.schemas`` in older releases)."""
    return optional("foxglove.messages") or require("foxglove.schemas", "--live")


def _timestamp(m: ModuleType, stamp_ns: int) -> object:
    return m.Timestamp(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)


def _image(m: ModuleType, stamp: object, frame_id: str, data: np.ndarray, encoding: str) -> object:
    """A RawImage of a (H, W) float32 map (``32FC1``) or an (H, W, 3) uint8 image (``rgb8``)."""
    data = np.ascontiguousarray(data)
    h, w = data.shape[:2]
    return m.RawImage(
        timestamp=stamp,
        frame_id=frame_id,
        width=w,
        height=h,
        encoding=encoding,
        step=data.strides[0],
        data=data.tobytes(),
    )


def _depth_image(m: ModuleType, stamp: object, frame_id: str, depth: np.ndarray) -> object:
    """``32FC1`` metres, little-endian, holes (<= 0) NaN (REP 118)."""
    d = np.asarray(depth, dtype="<f4")
    return _image(m, stamp, frame_id, np.where(d > 0, d, np.float32(np.nan)).astype("<f4"), "32FC1")


#: The PointCloud layout: x, y, z float32 and red, green, blue, alpha uint8 (16 bytes a point).
_CLOUD_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1"), ("alpha", "u1")]
)


def _cloud(m: ModuleType, stamp: object, frame_id: str, cloud: PointCloud) -> object:
    """A foxglove PointCloud of a :class:`semattnet.geometry.PointCloud` (grey where it has no colours)."""
    packed = np.zeros(len(cloud.xyz), _CLOUD_DTYPE)
    for i, axis in enumerate("xyz"):
        packed[axis] = cloud.xyz[:, i]
    rgb = cloud.rgb if cloud.rgb is not None else np.full((len(cloud.xyz), 3), 200, np.uint8)
    for i, channel in enumerate(("red", "green", "blue")):
        packed[channel] = rgb[:, i]
    packed["alpha"] = 255
    T = m.PackedElementFieldNumericType
    fields = [
        m.PackedElementField(name=name, offset=offset, type=T.Float32 if name in "xyz" else T.Uint8)
        for name, (_, offset, *_) in (_CLOUD_DTYPE.fields or {}).items()
    ]
    pose = m.Pose(position=m.Vector3(x=0.0, y=0.0, z=0.0), orientation=m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
    return m.PointCloud(
        timestamp=stamp,
        frame_id=frame_id,
        pose=pose,
        point_stride=_CLOUD_DTYPE.itemsize,
        fields=fields,
        data=packed.tobytes(),
    )


def _calibration(m: ModuleType, stamp: object, frame_id: str, info: CameraInfoData) -> object:
    """A CameraCalibration of a :class:`semattnet.geometry.cameras.CameraInfoData`."""

    def flat(a: np.ndarray) -> list[float]:
        return [float(v) for v in np.asarray(a, dtype=np.float64).ravel()]

    return m.CameraCalibration(
        timestamp=stamp,
        frame_id=frame_id,
        width=int(info.width),
        height=int(info.height),
        distortion_model=str(info.distortion_model or "plumb_bob"),
        D=flat(info.D),
        K=flat(info.K),
        R=flat(info.R),
        P=flat(info.P),
    )


def _transform(m: ModuleType, stamp: object, parent: str, child: str, T_parent_child: np.ndarray) -> object:
    """FrameTransforms with one transform: ``child`` in ``parent`` (p_parent = T p_child)."""
    from semattnet.robotics.bags.tf import matrix_to_quaternion

    T = np.asarray(T_parent_child, dtype=np.float64)
    x, y, z, w = matrix_to_quaternion(T[:3, :3])
    t = [float(v) for v in T[:3, 3]]
    tf = m.FrameTransform(
        timestamp=stamp,
        parent_frame_id=parent,
        child_frame_id=child,
        translation=m.Vector3(x=t[0], y=t[1], z=t[2]),
        rotation=m.Quaternion(x=x, y=y, z=z, w=w),
    )
    return m.FrameTransforms(transforms=[tf])


class _Server(Protocol):
    """What the sink uses of a running foxglove server."""

    @property
    def port(self) -> int: ...

    def stop(self) -> None: ...


#: Seconds :meth:`LiveSink.finish` waits for the server to stop (it has no client left by then).
STOP_S = 5.0


def _bounded(fn: Callable[[], object], seconds: float) -> bool:
    """Call ``fn`` in a daemon thread and wait at most ``seconds``; whether it returned."""
    import threading

    thread = threading.Thread(target=fn, name="semattnet-stop", daemon=True)
    thread.start()
    thread.join(seconds)
    return not thread.is_alive()


class _Channel(Protocol):
    """What the sink uses of a foxglove channel."""

    def has_sinks(self) -> bool: ...

    def log(self, msg: object, *, log_time: int) -> None: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class LiveOptions(SinkOptions):
    """``--live [HOST:]PORT``."""

    needs_intrinsics: ClassVar[bool] = True
    clouds: ClassVar[str] = "always"
    live: str | None = option(
        "--live",
        type="address",
        identity=False,
        help="Serve the frames as they are completed over the Foxglove WebSocket protocol "
        "(HOST: 127.0.0.1 unless given).  [extra: live]",
    )

    def sinks(self, settings: OutputSettings) -> list[Sink]:
        if self.live is None:
            return []
        s = settings
        return [LiveSink(address=self.live, max_depth=s.max_depth, log=s.log, max_uncertainty=s.max_uncertainty)]


@register_sink("live", option="--live", options=LiveOptions)
@dataclass
class LiveSink(RunSink):
    """``--live [HOST:]PORT``: serve each completed frame over the Foxglove WebSocket protocol (module doc).

    Args:
        address: ``[HOST:]PORT`` to listen on (port 0: a free port, see :attr:`port`).
        max_depth: completed-cloud points deeper than this are left out, metres (None: all).
        prefix: the topics of the outputs (``PREFIX/depth``, ...).
        max_uncertainty: completed-cloud points whose uncertainty exceeds it are left out (None: all).
    """

    address: str = "127.0.0.1:8765"
    max_depth: float | None = None
    prefix: str = "/semattnet"
    #: Where the address to connect to is said once the server runs (e.g. ``print``).
    log: Callable[[str], object] | None = None
    max_uncertainty: UncertaintyLimit | None = None
    #: Frames kept from an earlier (resumed) run are not re-sent.
    replays: ClassVar[bool] = False
    _server: _Server | None = field(default=None, init=False, repr=False)
    _gate: Gate | None = field(default=None, init=False, repr=False)
    _channels: dict[str, _Channel] = field(default_factory=dict, init=False, repr=False)
    _context: object = field(default=None, init=False, repr=False)  # kept alive: channels die with their context
    _count: int = field(default=0, init=False, repr=False)

    def reads(self) -> frozenset[str]:
        """The depth and the uncertainty (sent to the clients that subscribe to it; RobotFrame's cloud)."""
        return RobotFrame.reads(uncertainty=True)

    @property
    def topics(self) -> dict[str, str]:
        """Topic by role (:data:`CHANNEL_TOPICS` with the prefix)."""
        return {k: v.replace("PREFIX", self.prefix.rstrip("/")) for k, v in CHANNEL_TOPICS.items()}

    @property
    def port(self) -> int:
        """The port the server listens on (after :meth:`open`)."""
        if self._gate is None:
            raise InputError("LiveSink.port: the server is not running (call open() first)")
        return self._gate.port

    @property
    def url(self) -> str:
        """``ws://HOST:PORT`` to connect the Foxglove app to (after :meth:`open`)."""
        host = parse_address(self.address, "live address")[0]
        return f"ws://{f'[{host}]' if ':' in host else host}:{self.port}"

    def open(self, overwrite: bool = False) -> None:
        """Start the server and advertise the channels (``overwrite`` means nothing here)."""
        fg = _foxglove()
        host, port = parse_address(self.address, "live address")
        self._context = context = fg.Context()
        newer = {"message_backlog_size": CLIENT_BACKLOG}  # older foxglove-sdk releases lack it
        try:  # the server on a private loopback port, the clients through the gate on the address asked for
            self._server = server = call_with_newer(
                fg.start_server, newer, name="semattnet", host="127.0.0.1", port=0, context=context
            )
            self._gate = Gate(host, port, ("127.0.0.1", int(server.port)))
            self._gate.start()
        except (RuntimeError, OSError) as e:
            self._stop()
            reason = (str(e).removeprefix("FoxgloveError: ").splitlines() or [type(e).__name__])[0]
            raise InputError(f"live address {self.address!r}: cannot serve there ({reason})") from None
        ch, topics = fg.channels, self.topics
        self._count = 0
        self._channels = {
            "depth": ch.RawImageChannel(topics["depth"], context=context),
            "uncertainty": ch.RawImageChannel(topics["uncertainty"], context=context),
            "points": ch.PointCloudChannel(topics["points"], context=context),
            "camera_info": ch.CameraCalibrationChannel(topics["camera_info"], context=context),
            "latency": fg.Channel(topics["latency"], schema=LATENCY_SCHEMA, context=context),
            "tf": ch.FrameTransformsChannel(topics["tf"], context=context),
            "rgb": ch.RawImageChannel(topics["rgb"], context=context),
            "sparse": ch.RawImageChannel(topics["sparse"], context=context),
        }
        if self.log is not None:
            if not is_loopback(host):
                self.log(exposed("--live", host, self.url))
            self.log(f"live view: {self.url} (Foxglove: Open connection, Foxglove WebSocket, this URL)")

    def subscribed(self, role: str = "depth") -> bool:
        """Whether a client is subscribed to ``role``'s channel (:data:`CHANNEL_TOPICS`) now."""
        channel = self._channels.get(role)
        return channel is not None and bool(channel.has_sinks())

    def _log(self, role: str, stamp_ns: int, build: Callable[[], object]) -> None:
        """Build and log a message on ``role``'s channel, only when a client subscribes to it."""
        channel = self._channels[role]
        if channel.has_sinks():
            channel.log(build(), log_time=stamp_ns)

    def write(self, stage: Path, pred: Prediction) -> None:
        """Log one frame (module doc)."""
        if self._server is None:
            raise InputError("LiveSink.write: the server is not running (call open() first)")
        frame, m = pred.frame, _messages()
        t_ns = stamp_ns(frame, self._count)
        self._count += 1
        stamp = _timestamp(m, t_ns)
        frame_id, info = frame_camera(frame)
        self._log("depth", t_ns, lambda: _depth_image(m, stamp, frame_id, pred.stored))
        unc_png = pred.uncertainty_png
        if unc_png is not None:
            self._log("uncertainty", t_ns, lambda: _depth_image(m, stamp, frame_id, decode_depth(unc_png)))
        self._log("rgb", t_ns, lambda: _image(m, stamp, frame_id, np.asarray(frame.rgb, np.uint8), "rgb8"))
        self._log("sparse", t_ns, lambda: _depth_image(m, stamp, frame_id, frame.sparse))
        if frame.K is not None:  # the cloud every robot output sends (RobotFrame), built when a client wants it
            self._log("points", t_ns, lambda: _cloud(m, stamp, frame_id, self._robot(pred).cloud))
        if info is not None:
            self._log("camera_info", t_ns, lambda: _calibration(m, stamp, frame_id, info))
        T = None if frame.calib is None else frame.calib.T_cam_lidar
        if T is not None:
            lidar = frame.meta.lidar_frame_id or "lidar"
            self._log("tf", t_ns, lambda: _transform(m, stamp, frame_id, lidar, T))
        stages = {str(k): float(v) for k, v in pred.stage_ms.items()}
        self._log("latency", t_ns, lambda: {"frame": frame.name, "stamp_ns": t_ns, "stages_ms": stages})

    def _robot(self, pred: Prediction) -> RobotFrame:
        return RobotFrame.of(
            pred, self._count, max_depth=self.max_depth, max_uncertainty=self.max_uncertainty, output="the live view"
        )

    def _stop(self) -> None:
        """Drop the clients (the gate), then stop the server: bounded whatever the clients do."""
        server, self._server, gate, self._gate = self._server, None, self._gate, None
        channels, self._channels, self._context = self._channels, {}, None
        for channel in channels.values():
            channel.close()
        if gate is not None:
            gate.close()
        if server is not None and not _bounded(server.stop, STOP_S) and self.log is not None:
            self.log(f"live view: the server did not stop within {STOP_S:g} s; left to end with the process")

    def finish(self, stage: Path) -> None:
        """Every frame sent; the server keeps serving until :meth:`close` (after ``frames.json`` is complete)."""

    def close(self) -> None:
        """Drop the clients and stop the server (within seconds, whatever the clients do)."""
        self._stop()

    def abort(self) -> None:
        """Close the server; never raises."""
        try:
            self._stop()
        except Exception:  # the run is failing already; a server that will not stop must not hide why
            pass
