"""Prediction and pictures for a user's frames: ``predict``, ``visualize``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from semattnet.cli._dataset import dataset_option
from semattnet.cli._group import main
from semattnet.cli._options import (
    DEPTH_M,
    PIXELS,
    SECONDS,
    SPEED,
    backend_option,
    check_precision_options,
    precision_options,
    require_with,
    weights_input,
    weights_option,
)

if TYPE_CHECKING:
    from semattnet.inference.pipeline import Completer


def _completer(method: str, weights: str | None, device: str, amp: str, backend: str = "torch",
               precision: str | None = None, calibration: Path | None = None) -> Completer:  # fmt: skip
    """The one completer the options name: the classical baseline or a DepthCompleter of --weights."""
    from semattnet._utils.distributed import process_device
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.cli._options import model_from_options
    from semattnet.inference import DepthCompleter

    if method == "classical":
        return ClassicalCompleter()
    _check_method(method, weights)
    model = model_from_options(weights, "cpu")
    return DepthCompleter(model, device=process_device(device), amp=amp, backend=backend, inplace=True,
                          precision=precision, calibration=calibration)  # fmt: skip


def _check_method(method: str, weights: str | None) -> None:
    """The model options agree (checked before any work): no option that would be ignored."""
    if method == "classical":
        if weights is not None:
            raise click.UsageError("--method classical uses no model: drop --checkpoint / --weights")
        # no semantic map, engine or precision: a spec, backend or --amp given with it would be ignored unread
        require_with("--method semattnet", False, "segment_spec", "backend", "amp")
        return
    if weights is None:
        raise click.UsageError("--checkpoint or --weights is required (or --method classical)")


def _intrinsics(text: str | None):
    """--K as a (3, 3) matrix, or None."""
    from semattnet._errors import SemAttNetError
    from semattnet.viz.viewer import parse_intrinsics

    try:
        return parse_intrinsics(text) if text else None
    except SemAttNetError as exc:
        raise click.BadParameter(str(exc), param_hint="--K") from None
    except ValueError:
        raise click.BadParameter(f"expected fx,fy,cx,cy or kitti, got {text!r}", param_hint="--K") from None


_INPUT = click.Path(exists=True, path_type=Path)


class _MaxUncertainty(click.ParamType):
    """``--max-uncertainty``: metres (``0.5``) or a percentage of the depth (``5%``), returned in a canonical
    text (:class:`semattnet.inference.uncertainty.UncertaintyLimit`'s), which the run identity records."""

    name = "METRES|PERCENT%"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        from semattnet._errors import InputError
        from semattnet.inference.uncertainty import UncertaintyLimit

        try:
            return str(UncertaintyLimit.parse(value))
        except InputError as exc:
            self.fail(str(exc), param, ctx)


#: The options of a ROS bag input and of the robot outputs (``--bag-out``, ``--rerun``) and ``--stream``.
_BAG_OPTIONS = [
    click.option("--bag", type=_INPUT, default=None,
                 help="A ROS 1 .bag, a ROS 2 bag folder or a .db3 / .mcap file (instead of --rgb/--sparse)."),
    click.option("--image-topic", default=None, help="With --bag: sensor_msgs/Image or CompressedImage topic."),
    click.option("--points-topic", default=None, help="With --bag: sensor_msgs/PointCloud2 topic (x, y, z)."),
    click.option("--camera-info-topic", default=None,
                 help="With --bag: sensor_msgs/CameraInfo topic [the bag's only one]."),
    click.option("--rig", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
                 help="With --bag: rig JSON (K, T_cam_lidar, image_size) overriding CameraInfo and /tf_static."),
    click.option("--semantic-topic", default=None,
                 help="With --bag: colour-coded semantic images, paired with the images by stamp."),
    click.option("--max-skew", type=SECONDS, default=None,
                 help="With --bag: seconds between an image and its scan at most [half the scan period]."),
    click.option("--list-topics", is_flag=True, help="With --bag: print the bag's topics and exit."),
    click.option("--bag-out", type=click.Path(path_type=Path), default=None,
                 help="Also write a ROS 2 bag (MCAP; ROS 1 for .bag): depth 32FC1, coloured cloud, CameraInfo."),
    click.option("--rerun", "rerun_file", type=click.Path(dir_okay=False, path_type=Path), default=None,
                 help="Also write a Rerun recording FILE.rrd.  [extra: rerun]"),
    click.option("--rerun-spawn", is_flag=True, help="Stream the frames to a spawned Rerun viewer."),
    click.option("--stream", is_flag=True,
                 help="Read, project and segment the next frames in a background thread while one is completed."),
    click.option("--rerun-serve", is_flag=True,
                 help="Serve the frames to Rerun's web viewer in a browser as they are completed.  [extra: rerun]"),
    click.option("--live", default=None, metavar="[HOST:]PORT",
                 help="Serve the frames as they are completed over the Foxglove WebSocket protocol.  [extra: live]"),
    click.option("--realtime", is_flag=True,
                 help="Replay at the recorded rate: frames that come while the completer is busy are dropped."),
    click.option("--speed", type=SPEED, default=None, help="With --realtime: replay this many times faster."),
]  # fmt: skip

#: The options that do not change what a run writes: a resumed run may differ from the first in these only.
_NOT_IDENTITY = {"resume", "overwrite", "on_error", "stream", "live", "rerun_serve", "rerun_spawn", "realtime",
                 "speed", "list_topics", "out"}  # fmt: skip


def _bag_options(f):
    for option in reversed(_BAG_OPTIONS):
        f = option(f)
    return f


def _check_inputs(rgb: Path | None, sparse: Path | None, kitti_raw: Path | None, data_root: Path | None,
                  bag: dict[str, Any]) -> None:  # fmt: skip
    """Exactly one input kind, and the options each needs."""
    folder = rgb is not None or sparse is not None
    kinds = folder + (kitti_raw is not None) + (bag["bag"] is not None) + (data_root is not None)
    if kinds != 1 or (folder and None in (rgb, sparse)):
        raise click.UsageError("give --rgb and --sparse, or --kitti-raw, or --bag, or --data (with --dataset)")
    bag_only = [k for k in ("image_topic", "points_topic", "camera_info_topic", "rig", "semantic_topic", "max_skew")
                if bag[k] is not None] + (["list_topics"] if bag["list_topics"] else [])  # fmt: skip
    if bag["bag"] is None and bag_only:
        raise click.UsageError(f"--{bag_only[0].replace('_', '-')} needs --bag")
    if bag["bag"] is not None and not bag["list_topics"] and None in (bag["image_topic"], bag["points_topic"]):
        raise click.UsageError("--bag needs --image-topic and --points-topic (see --list-topics)")


def _source(rgb, sparse, kitti_raw, frames, camera, semantic, deskew, K, bag, data):
    """The frame source the options name; ``data``: (dataset name, root or None, split)."""
    from semattnet.data.sources import FolderSource, RawDriveSource
    from semattnet.robotics import BagSource

    dataset, data_root, split = data
    if data_root is not None:
        from semattnet.data.datasets import get_dataset

        return get_dataset(dataset).source(data_root, split, semantic_root=semantic)
    if bag["bag"] is not None:
        return BagSource(bag["bag"], bag["image_topic"], bag["points_topic"], bag["camera_info_topic"], bag["rig"],
                         bag["max_skew"], bag["semantic_topic"], log=click.echo)  # fmt: skip
    if kitti_raw is not None:
        return RawDriveSource(kitti_raw, frames, camera, semantic, deskew)
    return FolderSource.pair(rgb, sparse, semantic, K=K, missing_ok=True)


def _eval_split(dataset: str) -> str:
    from semattnet.data.datasets import get_dataset

    return get_dataset(dataset).eval_split


def _robot_sinks(bag: dict[str, Any], max_depth: float, timer: Any, limit: Any = None) -> list[Any]:
    """``latency.json`` and, as asked, the bag, the Rerun recording or viewer and the live server (``limit``:
    the :class:`~semattnet.inference.uncertainty.UncertaintyLimit` of their clouds, or None)."""
    from semattnet.inference.sinks import LatencySink
    from semattnet.robotics.sinks import BagSink, RerunSink

    sinks: list[Any] = [LatencySink(timer=timer)]
    unc = bool(bag["uncertainty"])
    if bag["bag_out"] is not None:
        sinks.append(BagSink(target=bag["bag_out"], max_depth=max_depth, uncertainty=unc, max_uncertainty=limit))
    if bag["rerun_file"] is not None or bag["rerun_spawn"] or bag["rerun_serve"]:
        sinks.append(RerunSink(target=bag["rerun_file"], spawn=bag["rerun_spawn"], serve=bag["rerun_serve"],
                               max_depth=max_depth, log=click.echo, uncertainty=unc,
                               max_uncertainty=limit))  # fmt: skip
    if bag["live"] is not None:
        from semattnet.robotics.live import LiveSink

        sinks.append(LiveSink(address=bag["live"], max_depth=max_depth, log=click.echo, max_uncertainty=limit))
    return sinks


def _identity(params: dict[str, Any]) -> dict[str, Any]:
    """What a run is, for a resume to check: every option that changes the outputs (paths resolved, a
    weights file by its SHA-256) and the package version."""
    from semattnet._utils.version import __version__
    from semattnet.cache import sha256_file

    run: dict[str, Any] = {"command": "predict", "version": __version__}
    for key, value in sorted(params.items()):
        if key in _NOT_IDENTITY or value is None or value is False:
            continue
        if key == "weights" and Path(value).is_file():  # a file by its digest (--checkpoint arrives here too)
            value = f"sha256:{sha256_file(value)}"
        run[key] = str(Path(value).resolve()) if isinstance(value, Path) else value
    return run


def _out_and_resume(out: Path | None, resume: str | None) -> tuple[Path, bool]:
    """``--out OUT [--resume]`` or ``--resume OUT``: the output folder and whether to resume."""
    if resume and out is not None and Path(resume).resolve() != out.resolve():
        raise click.UsageError(f"--resume {resume} and --out {out} name two folders; give one")
    if resume:
        return Path(resume), True
    if out is None:
        raise click.UsageError("Missing option '--out'.")
    return out, resume is not None


@main.command()
@weights_option
@click.option("--rgb", type=_INPUT, default=None, help="PNG file or folder (with --sparse).")
@click.option("--sparse", type=_INPUT, default=None, help="16-bit PNG file or folder (with --rgb).")
@click.option(
    "--kitti-raw",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="A KITTI raw drive folder RAW_ROOT/DATE/DATE_drive_NNNN_sync (instead of --rgb/--sparse).",
)
@dataset_option("With --data: the dataset whose root --data is.")
@click.option("--data", "data_root", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="A dataset root (with --dataset; instead of --rgb/--sparse): the frames of --split.")  # fmt: skip
@click.option("--split", default=None, help="With --data: the split [the dataset's evaluation split].")
@click.option("--frames", default=None, help="With --kitti-raw: indices, a range a-b or a comma list (default all).")
@click.option("--camera", type=click.Choice(["2", "3"]), default="2", show_default=True, help="With --kitti-raw.")
@click.option("--semantic", type=_INPUT, default=None, help="PNG file or folder of colour-coded semantic maps.")
@click.option(
    "--segment",
    "segment_spec",
    default=None,
    metavar="SPEC",
    help="With --kitti-raw or --bag: segment each image with this model (see `semattnet segment --model`); "
    "with --data (nyuv2, void): the split's frames segmented once into a cache folder and reused.",
)
@click.option("--palette-mismatch", type=click.Choice(["refuse", "recolour", "fallback"]), default="refuse",
              show_default=True, help="Maps of another palette than the model's: refuse, recolour the classes both "
              "palettes name (the rest unknown), or use the fallback map (see evaluate).")  # fmt: skip
@_bag_options
@click.option("--out", default=None, type=click.Path(file_okay=False, path_type=Path), help="Output folder [required].")
@click.option("--npy", is_flag=True, help="Also write float32 .npy depth (and uncertainty, with --uncertainty).")
@click.option(
    "--uncertainty",
    is_flag=True,
    help="Also write the per-pixel uncertainty: OUT/uncertainty/NAME.png (metres * 256, 0 = none), "
    "in the bag (--bag-out) and the Rerun recording, and in the viewer (--report).",
)
@click.option(
    "--max-uncertainty",
    type=_MaxUncertainty(),
    default=None,
    help="Point clouds (--ply, bird's-eye view, --bag-out, --rerun, --live) leave out pixels whose "
    "uncertainty exceeds METRES, or PERCENT% of their depth; depth maps stay dense.",
)
@click.option("--panel", is_flag=True, help="Also write the per-branch panel (with --kitti-raw: a bird's-eye view).")
@click.option("--ply", is_flag=True, help="With --kitti-raw or --bag: also write a binary PLY point cloud.")
@click.option(
    "--max-depth",
    type=DEPTH_M,
    default=80.0,
    show_default=True,
    help="PLY / bird's-eye view: drop deeper pixels, m.",
)
@click.option(
    "--top-crop", type=PIXELS, default=0, show_default=True, help="PLY / bird's-eye view: drop the top N rows (sky)."
)
@click.option("--deskew", is_flag=True, help="With --kitti-raw: ego-motion compensate scans with their OXTS data.")
@click.option("--device", default="auto", show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@backend_option
@precision_options
@click.option("--overwrite", is_flag=True, help="Replace existing outputs.")
@click.option(
    "--resume",
    is_flag=False,
    flag_value="",
    default=None,
    metavar="[OUT]",
    help="Continue the killed or failed run in OUT (or --out): keep its completed frames, do the rest.",
)
@click.option(
    "--on-error",
    type=click.Choice(["skip", "stop"]),
    default=None,
    help="A frame that cannot be completed: skip it (named, counted; the default for several frames) "
    "or stop the run (the default for one frame; the frames done are kept).",
)
@click.option("--method", type=click.Choice(["semattnet", "classical"]), default="semattnet", show_default=True,
              help="classical: the non-learned IP-Basic-style baseline (no checkpoint).")  # fmt: skip
@click.option("--report", is_flag=True, help="Also write viewer.html: hover depths, layers, 3D view (with --K).")
@click.option("--K", "intrinsics", default=None, metavar="fx,fy,cx,cy|kitti",
              help="With --report: camera intrinsics for the 3D view ('kitti': KITTI's camera 02).")  # fmt: skip
def predict(weights: str | None, rgb: Path | None, sparse: Path | None,
            kitti_raw: Path | None, frames: str | None, camera: str, semantic: Path | None, segment_spec: str | None,
            out: Path | None, npy: bool, panel: bool, ply: bool, max_depth: float, top_crop: int, deskew: bool,
            device: str, amp: str, backend: str, overwrite: bool, method: str, report: bool,
            intrinsics: str | None, **bag: Any) -> None:  # fmt: skip
    """Complete depth for one frame, folders of frames (any size), a KITTI split or raw drive, a dataset
    or a ROS bag.

    A frame that cannot be completed is skipped with one line (--on-error); OUT/frames.json records every
    frame. Exit status: 0 when every frame was done, 3 when some were skipped, 4 when --realtime dropped
    some (and none was skipped). Prints a per-stage latency table at the end and writes OUT/latency.json."""
    data = (bag.pop("dataset"), bag.pop("data_root"), bag.pop("split"))
    _check_inputs(rgb, sparse, kitti_raw, data[1], bag)
    if bag["list_topics"]:
        from semattnet.robotics.bags import format_topics, list_topics

        click.echo(format_topics(list_topics(bag["bag"])))
        return
    out, resuming = _out_and_resume(out, bag.pop("resume"))
    _check_combinations(rgb, sparse, kitti_raw, data, frames, deskew, ply, segment_spec, semantic, report,
                        intrinsics, bag)  # fmt: skip
    _check_uncertainty(ply, panel, kitti_raw is not None or bag["bag"] is not None, bag)
    if resuming and overwrite:
        raise click.UsageError("give --resume or --overwrite, not both")
    _check_method(method, weights)
    check_precision_options(method, amp, bag.pop("precision"), bag.pop("calibration"), backend)
    if method != "classical":
        from semattnet._utils.device import resolve_device

        resolve_device(device)  # a bad --device: one line, before any work
    run = _run_frames(click.get_current_context().params, out, resuming)
    import os

    from semattnet._utils.distributed import launch_rank

    if launch_rank() == 0:
        click.echo(run.summary())
    launched = int(os.environ.get("WORLD_SIZE", "1")) > 1  # torchrun takes any other status for a crash
    if run.exit_code and not launched:
        click.get_current_context().exit(run.exit_code)


def _check_combinations(rgb: Path | None, sparse: Path | None, kitti_raw: Path | None, data: tuple, frames: str | None,
                        deskew: bool, ply: bool, segment_spec: str | None, semantic: Path | None, report: bool,
                        intrinsics: str | None, bag: dict[str, Any]) -> None:  # fmt: skip
    """The options agree with the input kind (one line each, before any work)."""
    files_only = kitti_raw is None and bag["bag"] is None and data[1] is None
    if files_only and (ply or segment_spec):
        raise click.UsageError("--ply and --segment need --kitti-raw, --bag or --data")
    if data[1] is not None and ply:
        raise click.UsageError("--ply needs --kitti-raw or --bag")
    if kitti_raw is None and (frames or deskew):
        raise click.UsageError("--frames and --deskew need --kitti-raw")
    require_with("--kitti-raw", kitti_raw is not None, "camera")
    robot = bool(bag["bag_out"] or bag["rerun_file"] or bag["rerun_spawn"] or bag["rerun_serve"] or bag["live"])
    require_with("--report, --bag-out, --rerun or --live", report or robot, "intrinsics")

    if bag["bag"] is not None and semantic is not None:
        raise click.UsageError("--semantic is for --rgb/--kitti-raw; a bag's semantic maps come with --semantic-topic")
    if bag["semantic_topic"] is not None and segment_spec is not None:
        raise click.UsageError("give --semantic-topic or --segment, not both")
    if not files_only and report:
        raise click.UsageError("--report needs --rgb/--sparse (not yet --kitti-raw, --bag or --data)")
    if files_only and intrinsics is None and robot:
        raise click.UsageError("--bag-out, --rerun and --live need the intrinsics: --bag, --kitti-raw, or --K")
    if bag["speed"] is not None and not bag["realtime"]:
        raise click.UsageError("--speed needs --realtime")
    if bag["realtime"] and bag["bag"] is None and kitti_raw is None:
        raise click.UsageError("--realtime replays a recording: it needs --bag or --kitti-raw")


def _check_uncertainty(ply: bool, panel: bool, lidar: bool, bag: dict[str, Any]) -> None:
    """``--max-uncertainty`` only with an output that has a point cloud (``--panel``: its bird's-eye view, with
    the LiDAR of ``--kitti-raw`` / ``--bag``); with a bag or a Rerun recording, only with ``--uncertainty`` (a
    resume rebuilds the kept frames' clouds from their stored uncertainty)."""
    replayed = bool(bag["bag_out"] or bag["rerun_file"] or bag["rerun_spawn"] or bag["rerun_serve"])
    clouds = ply or (panel and lidar) or replayed or bag["live"] is not None
    require_with("--ply, --panel (with --kitti-raw or --bag), --bag-out, --rerun or --live", clouds,
                 "max_uncertainty")  # fmt: skip
    if bag["max_uncertainty"] is not None and replayed and not bag["uncertainty"]:
        raise click.UsageError("--max-uncertainty with --bag-out or --rerun needs --uncertainty (a resumed run "
                               "rebuilds the kept frames' clouds from OUT/uncertainty/)")  # fmt: skip


def _run_frames(p: dict[str, Any], out: Path, resuming: bool) -> Any:
    """Check everything, load the completer, run the one frame loop; then the table (and the report).
    ``p``: every option of the command, by name."""
    from semattnet._utils.distributed import launch_rank, process_group
    from semattnet.inference.pipeline import check_frames, complete_frames
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.sinks import default_sinks
    from semattnet.inference.timing import StageTimes
    from semattnet.inference.uncertainty import UncertaintyLimit

    K = _intrinsics(p["intrinsics"])
    folder, mismatch = p["semantic"] is not None or p["semantic_topic"] is not None, p["palette_mismatch"]
    maps = SemanticMaps(p["segment_spec"], folder=folder, mismatch=mismatch)
    semantic = p["semantic"]
    if p["data_root"] is not None and p["segment_spec"] is not None:  # the split's maps, cached: a folder
        from semattnet.segmentation.datasets import segment_split

        semantic = segment_split(p["dataset"], p["data_root"], (p["split"] or _eval_split(p["dataset"]),),
                                 p["segment_spec"], p["device"], log=click.echo)  # fmt: skip
        maps = SemanticMaps(None, folder=True, mismatch=mismatch)
    timer = StageTimes()
    limit = None if p["max_uncertainty"] is None else UncertaintyLimit.parse(p["max_uncertainty"])
    files = default_sinks(p["npy"], p["panel"], p["ply"], p["max_depth"], p["top_crop"], p["uncertainty"], limit)
    sinks = files + _robot_sinks(p, p["max_depth"], timer, limit)
    realtime = (p["speed"] or 1.0) if p["realtime"] else None
    inputs = (p["rgb"], p["sparse"], p["kitti_raw"], p["frames"], p["camera"], semantic, p["deskew"], K)
    with process_group():
        source = _source(*inputs, p, (p["dataset"], p["data_root"], p["split"]))
        plan = check_frames(source, sinks, out, overwrite=p["overwrite"], on_error=p["on_error"], resume=resuming,
                            run=_identity(p), inputs=[weights_input(p["weights"])[1]])  # before the model  # fmt: skip
        if plan.journal.kept:
            click.echo(f"{out}: resuming: {len(plan.journal.kept)} of {len(source.names)} frame(s) already done")
        completer = _completer(p["method"], p["weights"], p["device"], p["amp"], p["backend"], p["precision"],
                               p["calibration"])  # fmt: skip
        run = complete_frames(source, completer, sinks, out, overwrite=p["overwrite"], log=click.echo,
                              semantic=maps, checked=plan, timer=timer, prefetch=2 if p["stream"] else 0,
                              realtime=realtime)  # fmt: skip
    if launch_rank() == 0:
        click.echo(timer.table())
        if maps.note:
            click.echo(f"semantic maps: {maps.note}")
    if p["report"] and launch_rank() == 0:  # under torchrun: once, after every rank's frames are in place
        from semattnet.viz.viewer import write_prediction_report

        done = [source.frames[p.stem] for p in run.paths]
        write_prediction_report(out, done, K=K, log=click.echo)
    return run


@main.command()
@click.option("--pred", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--gt", type=click.Path(exists=True, path_type=Path), default=None, help="Ground truth: adds error maps.")
@click.option("--vmax", type=DEPTH_M, default=80.0, show_default=True, help="Depth of the colour scale's top, metres.")
@click.option("--overwrite", is_flag=True, help="Replace existing pictures.")
def visualize(pred: Path, out: Path, gt: Path | None, vmax: float, overwrite: bool) -> None:
    """Colourise saved depth predictions (and error maps against ground truth)."""
    from semattnet.viz.depth import write_depth_pictures

    count = write_depth_pictures(pred, out, gt, vmax, overwrite=overwrite)
    click.echo(f"wrote {count} picture(s) to {out}")
