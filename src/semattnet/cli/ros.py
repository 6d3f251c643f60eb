"""``semattnet ros2`` / ``semattnet ros1``: the live depth-completion node on a robot, over DDS (ROS 2) or the
ROS 1 master and TCPROS; no ROS installation needed for either.

The model options are the one "Model" section every command that runs a model takes (:mod:`semattnet.cli._model`),
the semantic-map options ``--segment`` / ``--palette-mismatch``, and the live viewers ``--live`` / ``--rerun-serve``
as their sink entries declare them; the node is :class:`semattnet.robotics.ros.node.DepthNode`.
"""

from __future__ import annotations

import functools
import logging
import os
import signal
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from semattnet.cli._group import main
from semattnet.cli._inputs import MAP_OPTIONS, Maps, field_options
from semattnet.cli._model import ModelOptions, model_options
from semattnet.cli._options import DEPTH_M, POSITIVE_FLOAT, POSITIVE_INT, SECONDS
from semattnet.cli._outputs import MaxUncertainty
from semattnet.cli._params import rehelp, section, values_of, with_options
from semattnet.cli._ros_params import PARAMS_OPTIONS, Ros1NodeCommand, RosNodeCommand

if TYPE_CHECKING:
    from semattnet.inference.contract import Completer
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.sinks import Sink
    from semattnet.inference.uncertainty import UncertaintyLimit
    from semattnet.robotics.ros.node import DepthNode
    from semattnet.robotics.ros.qos import QosOverride
    from semattnet.robotics.ros.transport import Transport

_ROS = section("ROS")


def viewer_options() -> Sequence[click.Parameter]:
    """``predict``'s live viewers, which run beside the node: ``--live`` (Foxglove) and ``--rerun-serve``, as their
    sink entries declare them."""
    from semattnet.robotics.live import LiveOptions
    from semattnet.robotics.sinks import RerunOptions

    made = field_options(LiveOptions, "Viewers") + field_options(RerunOptions, "Viewers")
    return tuple(p for p in made if p.name in ("live", "rerun_serve"))


#: The semantic-map options a live node takes (a segmenter; no map files).
SEGMENT_OPTIONS = tuple(
    rehelp(
        [p for p in MAP_OPTIONS if p.name in ("segment_spec", "palette_mismatch")],
        {
            "segment_spec": "Segment each camera image with this model (see `semattnet segment --model`) before it is "
            "completed [no segmenter: the fallback map].",
        },
    )
)

ROS2_OPTIONS = (
    _ROS(
        ["--image-topic"],
        default="~/input/image",
        show_default=True,
        help="sensor_msgs/Image (rgb8, bgr8, rgba8, bgra8, mono8, mono16, bayer_rggb8/bggr8/gbrg8/grbg8, yuv422, "
        "yuv422_yuy2); a name ending in /compressed: CompressedImage.",
    ),
    _ROS(["--camera-info-topic"], default="~/input/camera_info", show_default=True, help="sensor_msgs/CameraInfo."),
    _ROS(
        ["--points-topic"],
        default="~/input/point_cloud",
        show_default=True,
        help="sensor_msgs/PointCloud2 (x, y, z), or with --sparse-depth a sparse depth Image (32FC1 m, 16UC1 mm).",
    ),
    _ROS(["--sparse-depth"], is_flag=True, help="--points-topic is a sparse depth image in the camera's frame."),
    _ROS(
        ["--output-prefix"],
        default="~/output",
        show_default=True,
        help="Where depth_image, point_cloud, uncertainty and camera_info are published.",
    ),
    _ROS(["--namespace"], default="", help="The node's namespace (~ is NAMESPACE/NODE) [/]."),
    _ROS(["--node-name"], default="semattnet", show_default=True, help="The node's name."),
    _ROS(
        ["--rig"],
        type=click.Path(exists=True, dir_okay=False, path_type=Path),
        default=None,
        help="Rig JSON (K, T_cam_lidar, image_size) overriding CameraInfo and /tf_static.",
    ),
    _ROS(
        ["--max-skew"],
        type=SECONDS,
        default=None,
        help="Seconds between an image and its scan at most [half the scan period].",
    ),
    _ROS(["--max-depth"], type=DEPTH_M, default=None, help="The point cloud leaves out deeper pixels, m [none]."),
    _ROS(
        ["--max-uncertainty"],
        type=MaxUncertainty(),
        default=None,
        help="The point cloud leaves out pixels whose uncertainty exceeds METRES or PERCENT% of their depth.",
    ),
    _ROS(
        ["--report-every"],
        type=POSITIVE_FLOAT,
        default=5.0,
        show_default=True,
        help="Seconds between two latency and drop lines.",
    ),
    _ROS(["--frames"], type=POSITIVE_INT, default=None, help="Stop after this many frames [run until Ctrl-C]."),
    _ROS(
        ["--publish"],
        default="depth_image,point_cloud,uncertainty,camera_info",
        show_default=True,
        metavar="ROLE[,ROLE...]",
        help="The outputs published (uncertainty only when the method gives one).",
    ),
    _ROS(
        ["--cloud-stride"],
        type=POSITIVE_INT,
        default=4,
        show_default=True,
        help="The point cloud keeps every N-th pixel in both directions (1: every pixel).",
    ),
    _ROS(
        ["--latch-camera-info"],
        is_flag=True,
        help="Publish camera_info reliable and transient local, depth 1: a late subscriber gets it at once.",
    ),
)


class QosType(click.ParamType):
    """``--qos TOPIC:POLICY=VALUE[,POLICY=VALUE...]``: its overrides (:mod:`semattnet.robotics.ros.qos`)."""

    name = "qos"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> object:
        from semattnet._errors import InputError
        from semattnet.robotics.ros.qos import parse_qos_option

        if isinstance(value, tuple):  # already converted (a parameter file's qos_overrides)
            return value
        try:
            return parse_qos_option(str(value))
        except InputError as exc:
            self.fail(str(exc), param, ctx)


def _no_qos(ctx: click.Context, param: click.Parameter, value: tuple[object, ...]) -> tuple[object, ...]:
    """``ros1``'s ``--qos``: refused in one line (ROS 1 has no QoS)."""
    from semattnet.robotics.ros.qos import ROS1_NO_QOS

    if value:
        raise click.BadParameter(ROS1_NO_QOS, ctx, param)
    return value


#: The DDS transport's options (``ros2``).
DDS_OPTIONS = (
    _ROS(
        ["--qos"],
        type=QosType(),
        multiple=True,
        metavar="TOPIC:POLICY=VALUE[,...]",
        help="Override the QoS of one of the node's topics (an input's subscription or an output's publisher, "
        "named as the node resolves it: ~/output/point_cloud, /camera/image_raw): reliability=reliable|best_effort, "
        "durability=volatile|transient_local, depth=N, history=keep_last; the same as the rclcpp parameters "
        "qos_overrides.TOPIC.publisher|subscription.POLICY; repeatable, a later one wins "
        "[inputs best effort depth 5, outputs reliable depth 1].",
    ),
    _ROS(["--domain-id"], type=click.IntRange(0, 232), default=None, help="DDS domain [ROS_DOMAIN_ID, else 0]."),
    _ROS(
        ["--loopback"],
        is_flag=True,
        help="DDS traffic on the loopback interface only: unicast to 127.0.0.1, no multicast (also with "
        "ROS_LOCALHOST_ONLY=1 or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).",
    ),
)
#: The ROS 1 transport's options (``ros1``).
ROS1_OPTIONS = (
    _ROS(
        ["--master"], default=None, metavar="URI", help="The ROS master [ROS_MASTER_URI, else http://127.0.0.1:11311]."
    ),
    _ROS(["--qos"], multiple=True, hidden=True, callback=_no_qos),  # one line saying why, not "no such option"
    _ROS(
        ["--host"],
        default=None,
        help="The address peers reach this node at [ROS_IP, else ROS_HOSTNAME, else 127.0.0.1].",
    ),
)


def _domain_id(given: int | None) -> int:
    """``--domain-id``, else ``ROS_DOMAIN_ID``, else 0 (a bad environment value: a usage error)."""
    if given is not None:
        return given
    text = os.environ.get("ROS_DOMAIN_ID", "").strip() or "0"
    if not text.isdigit() or int(text) > 232:
        raise click.UsageError(f"ROS_DOMAIN_ID={text!r}: expected a domain id 0-232 (or give --domain-id)")
    return int(text)


@dataclass(frozen=True)
class NodeOptions:
    """The node's own options (:data:`ROS2_OPTIONS`), whatever its transport."""

    image_topic: str
    camera_info_topic: str
    points_topic: str
    sparse_depth: bool
    output_prefix: str
    namespace: str
    node_name: str
    rig: Path | None
    max_skew: float | None
    max_depth: float | None
    max_uncertainty: str | None
    report_every: float
    frames: int | None
    live: str | None
    rerun_serve: str | None
    publish: str = "depth_image,point_cloud,uncertainty,camera_info"
    cloud_stride: int = 4
    latch_camera_info: bool = False
    qos: tuple[tuple[QosOverride, ...], ...] = ()

    def viewers(self, limit: UncertaintyLimit | None) -> list[Sink]:
        """The live viewers asked for (``--live``, ``--rerun-serve``), made by their sink entries' options as
        ``predict`` makes them, fed every published frame."""
        import math

        from semattnet.inference.sinks import OutputSettings
        from semattnet.robotics.live import LiveOptions
        from semattnet.robotics.sinks import RerunOptions

        depth = self.max_depth if self.max_depth is not None else math.inf
        settings = OutputSettings(max_uncertainty=limit, max_depth=depth, log=click.echo)
        return [
            *LiveOptions(live=self.live).sinks(settings),
            *RerunOptions(rerun_serve=self.rerun_serve).sinks(settings),
        ]

    def node(self, completer: Completer, semantic: SemanticMaps, transport: Callable[[], Transport]) -> DepthNode:
        """The node on the transport ``transport()`` makes (the names and the rig checked first)."""
        from semattnet.geometry import read_rig_json
        from semattnet.inference.uncertainty import UncertaintyLimit
        from semattnet.robotics.ros.names import check_namespace, resolve_name
        from semattnet.robotics.ros.node import DepthNode, NodeTopics
        from semattnet.robotics.ros.publish import output_roles
        from semattnet.robotics.ros.qos import node_qos

        topics = NodeTopics(self.image_topic, self.camera_info_topic, self.points_topic, output=self.output_prefix)
        namespace = check_namespace(self.namespace)
        for option, name in (
            ("--image-topic", self.image_topic),
            ("--camera-info-topic", self.camera_info_topic),
            ("--points-topic", self.points_topic),
            ("--output-prefix", self.output_prefix),
        ):
            resolve_name(name, namespace, self.node_name, option)  # a bad name: one line, before the transport starts
        names = topics.resolved(namespace, self.node_name)
        refuse_topic_clashes(names)
        overrides = [o for given in self.qos for o in given]
        qos = node_qos(overrides, names, namespace, self.node_name, self.latch_camera_info)
        roles = output_roles([r.strip() for r in self.publish.split(",") if r.strip()])
        rig = read_rig_json(self.rig) if self.rig is not None else None
        limit = None if self.max_uncertainty is None else UncertaintyLimit.parse(self.max_uncertainty)
        return DepthNode(
            transport(),
            completer,
            topics,
            namespace=namespace,
            node=self.node_name,
            rig=rig,
            max_skew_ns=None if self.max_skew is None else round(self.max_skew * 1e9),
            compressed=self.image_topic.rstrip("/").endswith("/compressed"),
            sparse=self.sparse_depth,
            semantic=semantic,
            max_depth=self.max_depth,
            max_uncertainty=limit,
            report_s=self.report_every,
            say=click.echo,
            sinks=self.viewers(limit),
            publish=roles,
            cloud_stride=self.cloud_stride,
            latch_camera_info=self.latch_camera_info,
            qos=qos,
            rosout=bool(click.get_current_context().meta.get("semattnet.rosout", True)),
        )


#: The node's input topics by role, with the option naming each.
_INPUT_OPTIONS = {"image": "--image-topic", "camera_info": "--camera-info-topic", "scan": "--points-topic"}


def refuse_topic_clashes(names: Mapping[str, str]) -> None:
    """One line, before the transport starts, for a node that could only read what it should not: two inputs on one
    topic, or an input on one of its own outputs (``names``: :meth:`NodeTopics.resolved`)."""
    seen: dict[str, str] = {}
    outputs = {name for role, name in names.items() if role.startswith("out:")}
    for role, option in _INPUT_OPTIONS.items():
        name = names[role]
        if name in seen:
            raise click.UsageError(f"{option} {name} is also {seen[name]}: each input needs its own topic")
        if name in outputs:
            raise click.UsageError(
                f"{option} {name} is one of the node's own outputs (--output-prefix): it would read what it publishes"
            )
        seen[name] = option


def localhost_only(env: Mapping[str, str]) -> bool:
    """Whether the environment asks ROS 2 nodes to stay on this machine: ``ROS_LOCALHOST_ONLY=1`` (Humble) or
    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Jazzy on), as ``rmw`` implementations honour them."""
    range_ = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper()
    return env.get("ROS_LOCALHOST_ONLY", "").strip() == "1" or range_ == "LOCALHOST"


def _run(params: dict[str, object], transport: Callable[[], Transport]) -> None:
    """Check the model options, load the completer and spin the node on ``transport()`` until stopped."""
    from semattnet._startup import quiet_interrupts
    from semattnet.robotics.ros.node import run_node

    # Until the node's own handler (run_node): a Ctrl-C while the model loads is one line and the end, never a
    # KeyboardInterrupt that a library could swallow, leaving the node to start deaf to the signal already sent
    quiet_interrupts()
    model, options = values_of(ModelOptions, params), values_of(NodeOptions, params)
    model.check()
    maps = Maps(None, params["segment_spec"], str(params["palette_mismatch"]))  # type: ignore[arg-type]
    completer = model.completer()
    node = options.node(completer, maps.semantic_maps(folder=False).bind(completer), transport)
    run_node(node, options.frames)
    # End now: not when an abandoned frame's model returns, nor after the seconds torch takes to tear down (the
    # node ends within 2 s of SIGINT / SIGTERM); the node, its viewers and its transport are closed already.
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


@main.command(cls=RosNodeCommand, generated=[("frames", viewer_options)])
@with_options(ROS2_OPTIONS + DDS_OPTIONS + PARAMS_OPTIONS)
@model_options()
@with_options(SEGMENT_OPTIONS)
def ros2(**params: object) -> None:
    """Run a ROS 2 depth-completion node: subscribe a camera, its CameraInfo and a LiDAR, publish completed depth.

    Speaks DDS itself (cyclonedds: pip install 'semattnet[ros2]'), no ROS installation or sourced workspace.
    Completes the newest image-scan pair (older pairs are dropped and counted), publishes under
    --output-prefix with the image's stamp and frame id; Ctrl-C or SIGTERM stops it. Takes ROS 2's
    `--ros-args -r __ns:=/robot -r __node:=depth -r FROM:=TO -p KEY:=VALUE --params-file FILE` (what a launch
    file's Node() passes); each option is a parameter named with _ for -, and --qos is rclcpp's
    qos_overrides./TOPIC.publisher|subscription.POLICY parameters too."""
    domain = _domain_id(params["domain_id"])  # type: ignore[arg-type]
    loopback = bool(params["loopback"]) or localhost_only(os.environ)

    enclave = str(click.get_current_context().meta.get("semattnet.enclave", "/"))

    def dds() -> Transport:
        from semattnet.robotics.ros.dds import DdsTransport
        from semattnet.robotics.ros.names import check_namespace

        # the node in the ROS 2 graph (ros_discovery_info) by the names it runs under
        namespace, node = check_namespace(str(params["namespace"])), str(params["node_name"]).strip("/")
        return DdsTransport(domain, loopback=loopback, namespace=namespace, node_name=node, enclave=enclave)

    _run(params, dds)


@main.command(cls=Ros1NodeCommand, generated=[("frames", viewer_options)])
@with_options(ROS2_OPTIONS + ROS1_OPTIONS + PARAMS_OPTIONS)
@model_options()
@with_options(SEGMENT_OPTIONS)
def ros1(**params: object) -> None:
    """Run a ROS 1 depth-completion node: the same node as ros2, registered with a ROS master and speaking TCPROS
    itself (any Python, no rospy; pip install 'semattnet[ros]'). Topics, pairing, drops and outputs as ros2.
    Takes rosrun's words too (__ns:=/robot __name:=depth _KEY:=VALUE FROM:=TO), and --ros-args as ros2.
    ROS 1 has no QoS: ros2's --qos and qos_overrides parameters are refused (--latch-camera-info latches)."""
    master = str(params["master"] or os.environ.get("ROS_MASTER_URI") or "http://127.0.0.1:11311")
    host = params["host"]

    def tcpros() -> Transport:
        from semattnet.robotics.ros.names import check_namespace
        from semattnet.robotics.ros.tcpros import TcprosTransport

        # The node's ROS 1 name is in its namespace: two robots' nodes on one master must not share a name.
        name = check_namespace(str(params["namespace"])) + "/" + str(params["node_name"]).strip("/")
        # A peer's shutdown call (rosnode kill; roscore on a name clash) stops the node as SIGTERM does: exit 0
        stop = functools.partial(signal.raise_signal, signal.SIGTERM)
        return TcprosTransport(master, node_name=name, host=None if host is None else str(host), on_shutdown=stop)

    _run(params, tcpros)
