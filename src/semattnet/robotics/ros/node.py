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
sink lifecycle; publishing is a sink (:class:`~.publish.RosPublishSink`) beside the viewers.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import DataError
from semattnet.data.frames import Dropped, Frame, SensorMeta, sensor_frame
from semattnet.geometry import RigCalibration
from semattnet.geometry.cameras import CameraInfoData
from semattnet.inference.feed import FrameFault
from semattnet.inference.live import LiveRun, run_live
from semattnet.inference.sinks import Sink
from semattnet.robotics.frame import ROS_TYPES, TOPICS

from .diagnostics import DIAGNOSTICS_TOPIC, Diagnostics, node_health
from .inputs import Pair, PairingInputs, Stamped
from .names import resolve_name
from .publish import CLOUD_STRIDE, RosPublishSink, gives_uncertainty
from .qos import default_qos
from .rosout import ROSOUT_TOPIC, Rosout
from .status import NodeStatus, TopicStatus, udp_drops
from .transport import QoS, Transport

if TYPE_CHECKING:
    from semattnet.inference.contract import Completer
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.uncertainty import UncertaintyLimit

__all__ = ["DepthNode", "NodeTopics", "run_node"]

log = logging.getLogger("semattnet.ros")


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
        qos: the QoS of the topics by role (:meth:`NodeTopics.resolved`'s keys; :func:`~.qos.node_qos`), over
            :func:`~.qos.default_qos`.
        rosout: the report lines and the ``semattnet.ros`` log published on ``/rosout`` (:mod:`.rosout`).
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
        qos: Mapping[str, QoS] | None = None,
        rosout: bool = True,
    ) -> None:
        self.transport = transport
        self.completer = completer
        self.rig = rig
        self.semantic = semantic
        self.names = (topics or NodeTopics()).resolved(namespace, node)
        self.report_s = report_s
        self.say = say
        self.qos = {**default_qos(latch_camera_info), **(qos or {})}
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
            qos={role: self.qos[f"out:{role}"] for role in ROS_TYPES},
        )
        self.sinks: list[Sink] = [self.publisher, *sinks]
        self.run = LiveRun()
        # /diagnostics: published from the report tick (and on stop) with what node_health() reads of the node
        fqn = resolve_name("~", namespace, node).rstrip("/")
        self.diagnostics = Diagnostics(transport, fqn, report_s)
        published = [self.names[f"out:{role}"] for role in sorted(publish)]
        self.rosout = Rosout(transport, fqn, [*published, DIAGNOSTICS_TOPIC, ROSOUT_TOPIC]) if rosout else None
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
        inp = self.inputs
        self.publisher.advertise()
        self.diagnostics.advertise()
        if self.rosout is not None:
            self.rosout.advertise()
        image_type = "sensor_msgs/msg/CompressedImage" if inp.compressed else "sensor_msgs/msg/Image"
        self._subscribe("image", image_type, inp.on_image)
        self._subscribe("scan", "sensor_msgs/msg/Image" if inp.sparse else "sensor_msgs/msg/PointCloud2", inp.on_scan)
        if self.rig is None:
            self._subscribe("camera_info", "sensor_msgs/msg/CameraInfo", inp.on_camera_info)
            if not inp.sparse:
                self._subscribe("tf_static", "tf2_msgs/msg/TFMessage", inp.on_tf_static)
                self._subscribe("tf", "tf2_msgs/msg/TFMessage", inp.on_tf)
        return self

    def _subscribe(self, role: str, msgtype: str, callback: Callable[[object], None]) -> None:
        self.transport.subscribe(self.names[role], msgtype, self.qos[role], callback)

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
                self._say(self.report())
            if self.rosout is not None:
                self.rosout.publish_pending()

        if self.rosout is not None:
            self.rosout.attach()
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
                self._say(self.report(final=True))
            if self.rosout is not None:
                self.rosout.publish_pending()
                self.rosout.detach()

    def _say(self, line: str) -> None:
        """A report line: said, and on ``/rosout``."""
        self.say(line)
        if self.rosout is not None:
            self.rosout.line(line)

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
