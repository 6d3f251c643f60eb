"""The live depth-completion node: subscribes a camera, its CameraInfo and a LiDAR, publishes completed depth.

One :class:`DepthNode` over any :class:`~.transport.Transport` (DDS for ROS 2, ...). Inputs (names as
``rclcpp`` resolves them, :mod:`.names`; remappable):

- ``~/input/image``: ``sensor_msgs/Image`` (rgb8, bgr8, rgba8, bgra8, mono8, mono16, the Bayer patterns, yuv422:
  :data:`~semattnet.robotics.bags.decode.IMAGE_ENCODINGS`), or ``CompressedImage`` (``compressed``);
- ``~/input/camera_info``: ``sensor_msgs/CameraInfo`` (not needed with a rig);
- ``~/input/point_cloud``: ``sensor_msgs/PointCloud2`` (x, y, z), or a sparse depth ``Image`` (``sparse``);
- ``/tf_static`` and ``/tf`` (the newest per child frame): camera <- LiDAR (not needed with a rig or a sparse
  depth image).

Pairs are made by :class:`~.inputs.PairingInputs` (the bag pairing rules) into a single slot; the node's one
worker completes the newest pair and publishes, under ``~/output``, the topics of
:data:`semattnet.robotics.frame.TOPICS` (``depth_image`` 32FC1 metres with NaN holes, ``point_cloud`` xyz + rgb,
``uncertainty`` when the method gives one, ``camera_info``), each with the image's stamp and frame id, built
once by :class:`~semattnet.robotics.frame.RobotFrame`. A frame that cannot be completed (no transform, no point
in front of the camera, a size the CameraInfo disagrees with) is one logged line; the node goes on.

The node is a :class:`~semattnet.data.frames.LiveSource` (the newest pair, a replaced one ``dropped``) run by the
one frame loop for live frames (:func:`semattnet.inference.live.run_live`): the loop's fault rule, stage times and
sink lifecycle; publishing is a sink (:class:`RosPublishSink`) beside the viewers.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from semattnet._errors import DataError, InputError
from semattnet.data.frames import Dropped, Frame, SensorMeta, sensor_frame
from semattnet.geometry import RigCalibration
from semattnet.geometry.cameras import CameraInfoData
from semattnet.inference.feed import FrameFault
from semattnet.inference.live import LiveRun, run_live
from semattnet.inference.sinks import Prediction, RunSink, Sink
from semattnet.robotics.frame import ROS_TYPES, TOPICS, RobotFrame

from .diagnostics import Diagnostics, node_health
from .inputs import Pair, PairingInputs, Stamped
from .names import resolve_name
from .status import NodeStatus, TopicStatus, udp_drops
from .transport import LATCHED_QOS, OUTPUT_QOS, SENSOR_QOS, TF_QOS, TF_STATIC_QOS, Publisher, Transport

if TYPE_CHECKING:
    from semattnet.inference.contract import Completer
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.uncertainty import UncertaintyLimit
    from semattnet.robotics.bags.deps import Typestore

__all__ = [
    "CLOUD_STRIDE",
    "OUTPUT_ROLES",
    "DepthNode",
    "NodeTopics",
    "RosPublishSink",
    "gives_uncertainty",
    "output_roles",
    "run_node",
]

log = logging.getLogger("semattnet.ros")

#: The published cloud's default stride: every 4th pixel both ways (29k of 465k points at 375x1242, what a
#: costmap needs).
CLOUD_STRIDE = 4


@dataclass(frozen=True)
class NodeTopics:
    """The node's topic names before resolution (``~`` = ``NAMESPACE/NODE``)."""

    image: str = "~/input/image"
    camera_info: str = "~/input/camera_info"
    scan: str = "~/input/point_cloud"
    tf_static: str = "/tf_static"
    output: str = "~/output"
    tf: str = "/tf"

    def resolved(self, namespace: str = "", node: str = "semattnet") -> dict[str, str]:
        """Absolute names by role: the inputs and each output role of :data:`TOPICS` (``out:ROLE``)."""
        names = {k: resolve_name(getattr(self, k), namespace, node) for k in ("image", "camera_info", "scan")}
        names["tf_static"] = resolve_name(self.tf_static, namespace, node)
        names["tf"] = resolve_name(self.tf, namespace, node)
        out = resolve_name(self.output, namespace, node)
        names.update({f"out:{role}": f"{out}/{TOPICS[role]}" for role in ROS_TYPES})
        return names


#: The outputs ``--publish`` chooses among, by their topic names under ``~/output``, and their roles.
OUTPUT_ROLES = {TOPICS[role]: role for role in ROS_TYPES}


def output_roles(names: Collection[str] | None) -> frozenset[str]:
    """The roles of output topic names (``depth_image``, ``point_cloud``, ``uncertainty``, ``camera_info``;
    None: all of them).

    Raises:
        InputError: a name that is not one of them (one line naming it and the choices).
    """
    if names is None:
        return frozenset(ROS_TYPES)
    bad = [n for n in names if n not in OUTPUT_ROLES]
    if bad or not names:
        have = ", ".join(OUTPUT_ROLES)
        raise InputError(f"--publish {','.join(names)!r}: expected one or more of {have}, comma-separated")
    return frozenset(OUTPUT_ROLES[n] for n in names)


def gives_uncertainty(completer: object) -> bool | None:
    """Whether ``completer`` gives a per-pixel uncertainty: its ``gives_uncertainty`` (the classical baseline), a
    :class:`~semattnet.inference.DepthCompleter`'s ``compute_uncertainty``; None when it does not say."""
    for attr in ("gives_uncertainty", "compute_uncertainty"):
        value = getattr(completer, attr, None)
        if isinstance(value, bool):
            return value
    return None


class RosPublishSink(RunSink):
    """The node's topics as a run sink: each completed frame's messages (:class:`RobotFrame`, built once in the
    transport's type store) published under ``~/output``: the float depth (``predict --npy``'s, not the PNG's
    1/256 m steps), the cloud of every ``cloud_stride``-th pixel both ways leaving out pixels deeper than
    ``max_depth`` or above ``max_uncertainty``, the uncertainty, the CameraInfo (latched with ``latch_camera_info``);
    ``roles`` the ones published. ``uncertainty``: whether the completer gives one (False: never advertised; None,
    not known: advertised with the first frame that has one)."""

    replays = False

    def __init__(
        self,
        transport: Transport,
        names: dict[str, str],
        max_depth: float | None = None,
        max_uncertainty: UncertaintyLimit | None = None,
        *,
        roles: frozenset[str] = frozenset(ROS_TYPES),
        cloud_stride: int = CLOUD_STRIDE,
        latch_camera_info: bool = False,
        uncertainty: bool | None = True,
    ) -> None:
        if cloud_stride < 1:
            raise InputError(f"--cloud-stride: expected a positive number of pixels, got {cloud_stride}")
        self.transport, self.names = transport, names
        self.max_depth, self.max_uncertainty = max_depth, max_uncertainty
        self.roles = roles - ({"uncertainty"} if uncertainty is False else set())
        self.cloud_stride, self.uncertainty = cloud_stride, uncertainty
        self.qos = {role: OUTPUT_QOS for role in ROS_TYPES}
        if latch_camera_info:
            self.qos["camera_info"] = LATCHED_QOS
        self.publishers: dict[str, Publisher] = {}
        self.muted = False

    def mute(self) -> None:
        """Publish nothing more: the node stopped without waiting for the frame in hand, which is not sent if it
        ever finishes (the loop's ``close`` ends a spin only: a node spun again publishes again)."""
        self.muted = True

    def reads(self) -> frozenset[str] | None:
        return RobotFrame.reads("uncertainty" in self.roles, self.max_uncertainty)

    def advertise(self) -> None:
        """Advertise the output topics (before the inputs are subscribed); the uncertainty's only when the
        completer is known to give one."""
        for role in sorted(self.roles):
            if role != "uncertainty" or self.uncertainty:
                self._advertise(role)

    def _advertise(self, role: str) -> Publisher:
        topic = self.names[f"out:{role}"]
        pub = self.publishers[role] = self.transport.advertise(topic, ROS_TYPES[role], self.qos[role])
        return pub

    def write(self, stage: Path, pred: Prediction) -> None:
        if self.muted:
            return
        robot = RobotFrame.of(
            pred,
            uncertainty=pred.uncertainty is not None and "uncertainty" in self.roles,
            max_depth=self.max_depth,
            max_uncertainty=self.max_uncertainty,
            float_depth=True,
            cloud_stride=self.cloud_stride if "points" in self.roles else 0,
        )
        for role, msg in robot.messages(cast("Typestore", self.transport.typestore), self.roles).items():
            (self.publishers.get(role) or self._advertise(role)).publish(msg)


class DepthNode:
    """The node (module doc). :meth:`start` advertises and subscribes; :meth:`spin` runs the frame loop until a stop
    event; :meth:`close` ends the transport. As a :class:`~semattnet.data.frames.LiveSource`: :meth:`take` (the
    newest pair), :meth:`name`, :meth:`assemble` (the pair's frame).

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
        publish: the output roles published (:func:`output_roles`; default all).
        cloud_stride: the cloud's stride, pixels both ways.
        latch_camera_info: the CameraInfo published transient local (a late subscriber gets it at once).
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
        sinks: Sequence[Sink] = (),
        publish: frozenset[str] = frozenset(ROS_TYPES),
        cloud_stride: int = CLOUD_STRIDE,
        latch_camera_info: bool = False,
    ) -> None:
        self.transport = transport
        self.completer = completer
        self.rig = rig
        self.semantic = semantic
        self.names = (topics or NodeTopics()).resolved(namespace, node)
        self.report_s = report_s
        self.say = say
        self.inputs = PairingInputs(self.names, self._put, compressed, sparse, max_skew_ns)
        self.publisher = RosPublishSink(
            transport,
            self.names,
            max_depth,
            max_uncertainty,
            roles=publish,
            cloud_stride=cloud_stride,
            latch_camera_info=latch_camera_info,
            uncertainty=gives_uncertainty(completer),
        )
        self.sinks: list[Sink] = [self.publisher, *sinks]
        self.run = LiveRun()
        # /diagnostics: published from the report tick (and on stop) with what node_health() reads of the node
        self.diagnostics = Diagnostics(transport, resolve_name("~", namespace, node).rstrip("/"), report_s)
        self._slot: Pair | None = None
        self._dropped: list[Dropped] = []
        self._ready = threading.Condition()
        self._taken = 0  # pairs the worker took (done, skipped or in hand)
        self._in_hand = ""  # the frame the worker took last
        self._said_final = False

    @property
    def published(self) -> int:
        """Frames published so far."""
        return self.run.done

    @property
    def failed(self) -> int:
        """Frames that could not be completed so far."""
        return self.run.skipped

    def start(self) -> DepthNode:
        """Advertise the outputs and subscribe the inputs."""
        t, n, inp = self.transport, self.names, self.inputs
        self.publisher.advertise()
        self.diagnostics.advertise()
        image_type = "sensor_msgs/msg/CompressedImage" if inp.compressed else "sensor_msgs/msg/Image"
        t.subscribe(n["image"], image_type, SENSOR_QOS, inp.on_image)
        scan_type = "sensor_msgs/msg/Image" if inp.sparse else "sensor_msgs/msg/PointCloud2"
        t.subscribe(n["scan"], scan_type, SENSOR_QOS, inp.on_scan)
        if self.rig is None:
            t.subscribe(n["camera_info"], "sensor_msgs/msg/CameraInfo", SENSOR_QOS, inp.on_camera_info)
            if not inp.sparse:
                t.subscribe(n["tf_static"], "tf2_msgs/msg/TFMessage", TF_STATIC_QOS, inp.on_tf_static)
                t.subscribe(n["tf"], "tf2_msgs/msg/TFMessage", TF_QOS, inp.on_tf)
        return self

    def _put(self, pair: Pair) -> None:
        """The single slot: a newer pair replaces one still waiting (a note of it for the loop, which counts it)."""
        with self._ready:
            if self._slot is not None:
                why = "a newer pair arrived while the completer was busy (the node completes the newest)"
                self._dropped.append(Dropped(self.name(self._slot), why))
            self._slot = pair
            self._ready.notify()

    def take(self, timeout: float) -> Pair | Dropped | None:
        """The next note of a dropped pair, else the newest pair, waiting up to ``timeout`` seconds."""
        with self._ready:
            if self._slot is None and not self._dropped:
                self._ready.wait(timeout)
            if self._dropped:
                return self._dropped.pop(0)
            pair, self._slot = self._slot, None
            if pair is not None:
                self._taken += 1
                self._in_hand = self.name(pair)
            return pair

    def name(self, pair: Pair) -> str:
        """A pair's frame name: its image's stamp, nanoseconds."""
        return str(pair.image.stamp_ns)

    def spin(self, stop: threading.Event, frames: int | None = None) -> None:
        """Complete the newest pair until ``stop`` is set (or ``frames`` pairs were done, published or failed, in
        all); a report line every ``report_s`` seconds and a summary at the end."""
        last = [time.monotonic()]

        def tick() -> None:
            if time.monotonic() - last[0] >= self.report_s:
                last[0] = time.monotonic()
                self.diagnostics.publish(node_health(self))  # before the report line starts a new interval
                self.say(self.report())

        left = None if frames is None else max(0, frames - self.published - self.failed)
        try:
            run_live(
                self,
                self.completer,
                self.sinks,
                stop,
                self.run,
                semantic=self.semantic,
                frames=left,
                report=self._note,
                tick=tick,
            )
        finally:
            with self._ready:
                said, self._said_final = self._said_final, True
            if not said:
                self.diagnostics.publish(node_health(self), final=True)
                self.say(self.report(final=True))

    def _note(self, fault: FrameFault) -> None:
        if fault.status != "dropped":
            log.warning("%s", fault.reason)

    def status(self) -> NodeStatus:
        """A snapshot of the counts (:class:`~.status.NodeStatus`): what a report line or a diagnostics publisher
        reads. The stale pairs are the loop's ``dropped`` and the notes it has not taken yet (one count)."""
        c = self.inputs.counts
        waiting = self.inputs.waiting
        with self._ready:
            stale, slot, taken = self.run.dropped + len(self._dropped), int(self._slot is not None), self._taken
        done, failed = self.run.done, self.run.skipped
        frames = {"stale": stale, "completed": done, "failed": failed}
        topics = {
            role: TopicStatus(t.received, t.decoded, t.bad, t.lost, **(frames if role in ("image", "scan") else {}))
            for role, t in c.topics.items()
            if role in ("image", "scan") or t.received
        }
        drops = udp_drops() if self.transport.name == "dds" else None
        in_flight = waiting + slot + max(0, taken - done - failed)
        return NodeStatus(topics, done, failed, stale, c.unpaired, in_flight, drops, self.run.tally)

    def report(self, final: bool = False) -> str:
        """One line (:meth:`~.status.NodeStatus.line`): what became of the images received, bad messages, socket
        drops and per-stage latency (since the last line; ``final``: in total)."""
        return self.status().line(final)

    def in_hand(self) -> str | None:
        """The frame the worker is completing (its name), or None."""
        with self._ready:
            busy = self._taken > self.run.done + self.run.skipped
            return self._in_hand if busy else None

    def abandon(self) -> None:
        """The stop does not wait for the frame in hand: the sinks closed now (the publisher sends nothing more, the
        viewers stop serving), the summary said (not again if the worker ends)."""
        with self._ready:
            said, self._said_final = self._said_final, True
        self.publisher.mute()
        for sink in self.sinks[1:]:
            try:
                sink.abort()
            except Exception as exc:  # a viewer that will not stop must not keep the node up
                log.warning("closing %s: %s", type(sink).__name__, exc)
        if not said:
            self.say(self.report(final=True))

    def _calibration(self, pair: Pair, size: tuple[int, int]) -> tuple[RigCalibration, CameraInfoData]:
        """The pair's calibration and CameraInfo: the rig's, else its CameraInfo and the transforms."""
        from semattnet.robotics.bags.pairs import rig_camera_info

        image, scan = pair.image, pair.scan
        if self.rig is not None:
            return self.rig, rig_camera_info(self.rig, image.frame_id, image.stamp_ns)
        info = pair.camera_info
        if info is None:
            raise DataError(f"no CameraInfo on {self.names['camera_info']} yet")
        camera = image.frame_id or info.frame_id
        T = np.eye(4) if self.inputs.sparse else self.inputs.lookup(camera, scan.frame_id)
        return RigCalibration(info.intrinsics(True), T, size, camera=camera or None), info

    def _decoded(self, item: Stamped, role: str) -> np.ndarray:
        try:
            data = item.decode()
        except DataError:
            self.inputs.note_bad(role)
            raise
        self.inputs.note_decoded(role)
        return data

    def assemble(self, pair: Pair) -> Frame:
        """The frame of a pair (:func:`~semattnet.data.frames.sensor_frame`): the image and the scan decoded (here,
        in the worker: only the pairs completed are), the scan projected into the image, a sparse depth image as it
        is; a fault names the image (or the scan that cannot be decoded)."""
        image, scan = pair.image, pair.scan
        try:
            rgb, data = self._decoded(image, "image"), self._decoded(scan, "scan")
            h, w = rgb.shape[:2]
            calib, info = self._calibration(pair, (w, h))
            if (info.width, info.height) != (w, h):
                raise DataError(f"the image is {w}x{h}, the calibration says {info.width}x{info.height}")
            meta = SensorMeta(image.stamp_ns, image.frame_id or info.frame_id, scan.frame_id, scan.stamp_ns, info)
            points, sparse = (None, data) if self.inputs.sparse else (data, None)
            return sensor_frame(self.name(pair), rgb, meta, calib, points=points, sparse=sparse, where=scan.where)
        except DataError as exc:
            text = str(exc)
            named = text.startswith((image.where, scan.where))
            raise DataError(text if named else f"{image.where}: {text}") from None

    def close(self) -> None:
        """End the transport (its threads and sockets); the sinks were closed by the loop."""
        self.transport.close()


#: Seconds a stop waits for the frame in hand before it abandons it (SIGINT / SIGTERM end the node within 2 s).
STOP_GRACE_S = 1.0


def run_node(node: DepthNode, frames: int | None = None, grace_s: float = STOP_GRACE_S) -> bool:
    """Start ``node``, run its frame loop in a worker thread until Ctrl-C or SIGTERM (or ``frames`` done), then
    close it. A signal sets the stop event; the frame in hand gets ``grace_s`` seconds to finish, else it is
    abandoned (one line naming it), the summary is said, the viewers and the publisher closed and the transport
    ended all the same. Returns whether a frame was abandoned: its worker may still be inside the model, and the
    caller ends the process (the CLI: ``os._exit(0)`` after flushing)."""
    import signal

    stop = threading.Event()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    errors: list[BaseException] = []

    def work() -> None:  # the start too: a master that answers slowly never holds a signal
        try:
            node.start()
            node.spin(stop, frames)
        except BaseException as exc:  # raised in the caller's thread below
            errors.append(exc)

    try:
        worker = threading.Thread(target=work, name="semattnet-node-loop", daemon=True)
        worker.start()
        while worker.is_alive() and not stop.wait(0.1):
            pass
        worker.join(grace_s)
        if worker.is_alive():
            frame = node.in_hand()
            said = f"mid-frame: frame {frame} abandoned" if frame else "while starting: the start abandoned"
            node.say(f"stopped {said} after {grace_s:g} s")
            node.abandon()
            return True
        if errors:
            raise errors[0]
        return False
    finally:
        node.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
