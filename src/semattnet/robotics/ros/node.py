"""The live depth-completion node: subscribes a camera, its CameraInfo and a LiDAR, publishes completed depth.

One :class:`DepthNode` over any :class:`~.transport.Transport` (DDS for ROS 2, ...). Inputs (names as
``rclcpp`` resolves them, :mod:`.names`; remappable):

- ``~/input/image``: ``sensor_msgs/Image`` (rgb8, bgr8, mono8), or ``CompressedImage`` (``compressed``);
- ``~/input/camera_info``: ``sensor_msgs/CameraInfo`` (not needed with a rig);
- ``~/input/point_cloud``: ``sensor_msgs/PointCloud2`` (x, y, z), or a sparse depth ``Image`` (``sparse``);
- ``/tf_static``: camera <- LiDAR (not needed with a rig or a sparse depth image).

Pairs are made by :class:`~.inputs.PairingInputs` (the bag pairing rules) into a single slot; the node's one
worker completes the newest pair and publishes, under ``~/output``, the topics of
:data:`semattnet.robotics.frame.TOPICS` (``depth_image`` 32FC1 metres with NaN holes, ``point_cloud`` xyz + rgb,
``uncertainty`` when the method gives one, ``camera_info``), each with the image's stamp and frame id, built
once by :class:`~semattnet.robotics.frame.RobotFrame`. A frame that cannot be completed (no transform, no point
in front of the camera, a size the CameraInfo disagrees with) is one logged line; the node goes on.
"""

from __future__ import annotations

import logging
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from semattnet._errors import DataError
from semattnet.data.frames import Frame, SensorMeta
from semattnet.geometry import RigCalibration
from semattnet.geometry.cameras import CameraInfoData
from semattnet.robotics.frame import ROS_TYPES, TOPICS, RobotFrame

from .inputs import Pair, PairingInputs
from .names import resolve_name
from .transport import OUTPUT_QOS, SENSOR_QOS, TF_STATIC_QOS, Publisher, Transport

if TYPE_CHECKING:
    from semattnet.inference.contract import Completer
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.sinks import RunSink
    from semattnet.inference.uncertainty import UncertaintyLimit
    from semattnet.robotics.bags.deps import Typestore

__all__ = ["DepthNode", "NodeTopics", "StageStats", "run_node"]

log = logging.getLogger("semattnet.ros")

#: The worker's stages, in order.
NODE_STAGES = ("projection", "network", "publish")


@dataclass(frozen=True)
class NodeTopics:
    """The node's topic names before resolution (``~`` = ``NAMESPACE/NODE``)."""

    image: str = "~/input/image"
    camera_info: str = "~/input/camera_info"
    scan: str = "~/input/point_cloud"
    tf_static: str = "/tf_static"
    output: str = "~/output"

    def resolved(self, namespace: str = "", node: str = "semattnet") -> dict[str, str]:
        """Absolute names by role: the inputs and each output role of :data:`TOPICS` (``out:ROLE``)."""
        names = {k: resolve_name(getattr(self, k), namespace, node) for k in ("image", "camera_info", "scan")}
        names["tf_static"] = resolve_name(self.tf_static, namespace, node)
        out = resolve_name(self.output, namespace, node)
        names.update({f"out:{role}": f"{out}/{TOPICS[role]}" for role in ROS_TYPES})
        return names


@dataclass
class StageStats:
    """Per-stage latency since the last report and in total (constant memory, however long the node runs)."""

    period: dict[str, list[float]] = field(default_factory=dict)  # stage -> [count, sum ms, max ms]
    total: dict[str, list[float]] = field(default_factory=dict)

    def add(self, stage: str, ms: float) -> None:
        for table in (self.period, self.total):
            c = table.setdefault(stage, [0.0, 0.0, 0.0])
            c[0], c[1], c[2] = c[0] + 1, c[1] + ms, max(c[2], ms)

    @staticmethod
    def line(table: dict[str, list[float]]) -> str:
        """``stage mean/max ms, ...`` in :data:`NODE_STAGES` order."""
        parts = [f"{s} {c[1] / c[0]:.1f}/{c[2]:.1f}" for s in NODE_STAGES if (c := table.get(s)) and c[0]]
        return "ms mean/max: " + (", ".join(parts) or "none yet")


class DepthNode:
    """The node (module doc). :meth:`start` subscribes and advertises; :meth:`spin` runs the worker until a stop
    event; :meth:`close` ends the transport.

    Args:
        transport: what moves the messages.
        completer: the completer (classical or a DepthCompleter).
        topics: the names (remappable).
        namespace: how ``~`` and relative names resolve (with ``node``).
        node: the node's name.
        rig: calibration overriding CameraInfo and ``/tf_static``.
        max_skew_ns: image-scan tolerance (None: half the scan period).
        compressed: the image topic is ``CompressedImage``.
        sparse: the scan topic is a sparse depth image.
        semantic: bound semantic maps (fills the frames' maps), or None.
        max_depth: the cloud leaves out deeper pixels, metres.
        max_uncertainty: the cloud leaves out pixels above it.
        report_s: seconds between two report lines.
        say: where the report lines go.
        sinks: run outputs fed each completed frame beside the topics (``--live``, ``--rerun-serve``).
    """

    def __init__(
        self,
        transport: Transport,
        completer: Completer,
        topics: NodeTopics | None = None,
        *,
        namespace: str = "",
        node: str = "semattnet",
        rig: RigCalibration | None = None,
        max_skew_ns: int | None = None,
        compressed: bool = False,
        sparse: bool = False,
        semantic: SemanticMaps | None = None,
        max_depth: float | None = None,
        max_uncertainty: UncertaintyLimit | None = None,
        report_s: float = 5.0,
        say: Callable[[str], object] = print,
        sinks: Sequence[RunSink] = (),
    ) -> None:
        self.transport, self.completer, self.rig, self.semantic = transport, completer, rig, semantic
        self.names = (topics or NodeTopics()).resolved(namespace, node)
        self.max_depth, self.max_uncertainty, self.report_s, self.say = max_depth, max_uncertainty, report_s, say
        self.inputs = PairingInputs(self.names, self._put, compressed, sparse, max_skew_ns)
        self.stats = StageStats()
        self.published = self.failed = 0
        self._slot: Pair | None = None
        self._ready = threading.Condition()
        self._publishers: dict[str, Publisher] = {}
        self.sinks = list(sinks)

    def start(self) -> DepthNode:
        """Open the sinks, advertise the outputs and subscribe the inputs."""
        for sink in self.sinks:
            sink.open()
        t, n, inp = self.transport, self.names, self.inputs
        for role, msgtype in ROS_TYPES.items():
            self._publishers[role] = t.advertise(n[f"out:{role}"], msgtype, OUTPUT_QOS)
        image_type = "sensor_msgs/msg/CompressedImage" if inp.compressed else "sensor_msgs/msg/Image"
        t.subscribe(n["image"], image_type, SENSOR_QOS, inp.on_image)
        scan_type = "sensor_msgs/msg/Image" if inp.sparse else "sensor_msgs/msg/PointCloud2"
        t.subscribe(n["scan"], scan_type, SENSOR_QOS, inp.on_scan)
        if self.rig is None:
            t.subscribe(n["camera_info"], "sensor_msgs/msg/CameraInfo", SENSOR_QOS, inp.on_camera_info)
            if not inp.sparse:
                t.subscribe(n["tf_static"], "tf2_msgs/msg/TFMessage", TF_STATIC_QOS, inp.on_tf_static)
        return self

    def _put(self, pair: Pair) -> None:
        """The single slot: a newer pair replaces one still waiting (dropped, counted)."""
        with self._ready:
            if self._slot is not None:
                self.inputs.counts.stale += 1
            self._slot = pair
            self._ready.notify()

    def _take(self, timeout: float) -> Pair | None:
        with self._ready:
            if self._slot is None:
                self._ready.wait(timeout)
            pair, self._slot = self._slot, None
            return pair

    def spin(self, stop: threading.Event, frames: int | None = None) -> None:
        """Complete the newest pair until ``stop`` is set (or ``frames`` pairs were done, published or failed); a
        report line every ``report_s`` seconds and a summary at the end."""
        last = time.monotonic()
        try:
            while not stop.is_set() and (frames is None or self.published + self.failed < frames):
                pair = self._take(0.1)
                if pair is not None:
                    self.process(pair)
                if time.monotonic() - last >= self.report_s:
                    last = time.monotonic()
                    self.say(self.report(self.stats.period))
                    self.stats.period = {}
        finally:
            self.say(self.report(self.stats.total, final=True))

    def report(self, table: dict[str, list[float]], final: bool = False) -> str:
        """One line: frames published, drops, bad messages and per-stage latency."""
        c = self.inputs.counts
        head = "ros node stopped: " if final else "ros node: "
        return (
            f"{head}{self.published} frame(s) published, {c.stale} stale pair(s) dropped, {c.unpaired} image(s) "
            f"without a scan, {self.failed} frame(s) failed, {c.bad} bad message(s); "
            f"{self.stats.line(table)}"
        )

    def process(self, pair: Pair) -> None:
        """Complete one pair and publish it; a frame's fault is one logged line."""
        from semattnet._errors import SemAttNetError

        try:
            frame = self._frame(pair)
            self._complete(frame)
        except (SemAttNetError, ValueError) as exc:
            self.failed += 1
            text = str(exc)
            log.warning("%s", text if text.startswith(pair.image.where) else f"{pair.image.where}: {text}")

    def _calibration(self, pair: Pair) -> tuple[np.ndarray, np.ndarray, CameraInfoData]:
        """(K, T_cam_lidar, CameraInfo) of a pair: the rig's, else its CameraInfo and ``/tf_static``."""
        from semattnet.robotics.bags.pairs import rig_camera_info

        image, scan = pair.image, pair.scan
        if self.rig is not None:
            rig_info = rig_camera_info(self.rig, image.frame_id, image.stamp_ns)
            return np.asarray(self.rig.K, np.float64), np.asarray(self.rig.T_cam_lidar, np.float64), rig_info
        info = pair.camera_info
        if info is None:
            raise DataError(f"no CameraInfo on {self.names['camera_info']} yet")
        if self.inputs.sparse:
            return info.intrinsics(True), np.eye(4), info
        camera = image.frame_id or info.frame_id
        return info.intrinsics(True), self.inputs.tree.lookup(camera, scan.frame_id), info

    def _frame(self, pair: Pair) -> Frame:
        """The frame of a pair: the scan projected into the image (a sparse depth image as it is)."""
        from semattnet.geometry import project_points

        image, scan = pair.image, pair.scan
        K, T, info = self._calibration(pair)
        h, w = image.data.shape[:2]
        if (info.width, info.height) != (w, h):
            raise DataError(f"the image is {w}x{h}, the calibration says {info.width}x{info.height}")
        start = time.perf_counter()
        if self.inputs.sparse:
            sparse = scan.data
            if sparse.shape != (h, w):
                raise DataError(
                    f"{scan.where}: the sparse depth is {sparse.shape[1]}x{sparse.shape[0]}, the image {w}x{h}"
                )
            points = None
        else:
            sparse = project_points(scan.data, K, T, (w, h), name=scan.where)
            points = scan.data
        self.stats.add("projection", (time.perf_counter() - start) * 1e3)
        meta = SensorMeta(image.stamp_ns, image.frame_id or info.frame_id, scan.frame_id, scan.stamp_ns, info)
        calib = RigCalibration(K, T, (w, h), camera=image.frame_id or None)
        return Frame(
            str(image.stamp_ns),
            image.data,
            sparse,
            K=K,
            timestamp=image.stamp_ns / 1e9,
            points=points,
            calib=calib,
            meta=meta,
        )

    def _complete(self, frame: Frame) -> None:
        from semattnet.inference.sinks import predict_frame

        if self.semantic is not None:
            frame = self.semantic.fill(frame)
        start = time.perf_counter()
        completion = self.completer(frame.rgb, frame.sparse, frame.semantic)
        with warnings.catch_warnings():  # holes are NaN on the wire: the PNG's note on them is not for a node
            warnings.simplefilter("ignore", UserWarning)
            pred = predict_frame(frame, completion)
        self.stats.add("network", (time.perf_counter() - start) * 1e3)
        start = time.perf_counter()
        robot = RobotFrame.of(
            pred,
            uncertainty=pred.uncertainty_png is not None,
            max_depth=self.max_depth,
            max_uncertainty=self.max_uncertainty,
        )
        for role, msg in robot.messages(self.transport_typestore).items():
            self._publishers[role].publish(msg)
        for sink in self.sinks:
            sink.write(Path("."), pred)  # the live viewers write no file
        self.stats.add("publish", (time.perf_counter() - start) * 1e3)
        self.published += 1

    @property
    def transport_typestore(self) -> Typestore:
        """The type store the transport's messages belong to (TCPROS's ``typestore``, ROS 1 Noetic's; DDS's ``ts``;
        else ROS 2 Humble's): the messages are built in it, never converted on each publish."""
        from semattnet.robotics.bags.deps import rosbags_typestore

        store = getattr(self.transport, "typestore", None) or getattr(self.transport, "ts", None)
        return cast("Typestore", store or rosbags_typestore(False))

    def close(self) -> None:
        """End the sinks and the transport (its threads and sockets)."""
        try:
            for sink in self.sinks:
                sink.finish(Path("."))
        finally:
            self.transport.close()


def run_node(node: DepthNode, frames: int | None = None) -> None:
    """Start ``node`` and spin it until Ctrl-C or SIGTERM (or ``frames`` done), then close it: the signal only
    sets the stop event, so the frame in hand finishes, the summary is printed and the transport ends."""
    import signal

    stop = threading.Event()
    previous = {}
    on_main = threading.current_thread() is threading.main_thread()
    if on_main:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    try:
        node.start()
        node.spin(stop, frames)
    finally:
        node.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
