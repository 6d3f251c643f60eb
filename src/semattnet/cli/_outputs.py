"""What ``predict`` writes and how it runs: the output and run options, their checks and the sinks they ask for.

The rules that are about combinations (an output that needs what only some inputs give: intrinsics, a
LiDAR recording, frames the viewer can show) are written here once, against the chosen
:class:`~semattnet.cli._inputs.InputKind`'s declared facts, so they name the inputs from the table.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import click

from semattnet.cli._inputs import INPUTS, ChosenInput, or_list
from semattnet.cli._options import DEPTH_M, PIXELS, SPEED, require_with
from semattnet.cli._params import section, with_options

if TYPE_CHECKING:
    from semattnet.inference.sinks import Sink
    from semattnet.inference.timing import StageTimes
    from semattnet.inference.uncertainty import UncertaintyLimit

__all__ = ["OUTPUTS", "RUN", "Outputs", "RunOptions", "output_options"]

OUTPUTS, RUN = "Outputs", "Run"


class MaxUncertainty(click.ParamType):
    """``--max-uncertainty``: metres (``0.5``) or a percentage of the depth (``5%``), returned in a canonical
    text (:class:`semattnet.inference.uncertainty.UncertaintyLimit`'s), which the run identity records."""

    name = "METRES|PERCENT%"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> str:
        from semattnet._errors import InputError
        from semattnet.inference.uncertainty import UncertaintyLimit

        try:
            return str(UncertaintyLimit.parse(str(value)))
        except InputError as exc:
            self.fail(str(exc), param, ctx)


class Address(click.ParamType):
    """``--live`` / ``--rerun-serve``: ``[HOST:]PORT`` (:func:`semattnet.robotics.gate.parse_address`), returned
    as given; a malformed one is a one-line usage error."""

    name = "[HOST:]PORT"

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None) -> str:
        from semattnet._errors import InputError
        from semattnet.robotics.gate import parse_address

        try:
            parse_address(str(value), "address")
        except InputError as exc:
            self.fail(str(exc), param, ctx)
        return str(value)


#: Where ``--rerun-serve`` without a value serves the recording (Rerun's own default port, this machine only).
RERUN_SERVE = "127.0.0.1:9876"

_OUT, _RUN = section(OUTPUTS), section(RUN)

#: The output options, then the run options, in the order of ``predict --help``.
OUTPUT_OPTIONS = (
    _OUT(["--out"], default=None, type=click.Path(file_okay=False, path_type=Path), help="Output folder [required]."),
    _OUT(["--npy"], is_flag=True, help="Also write float32 .npy depth (and uncertainty, with --uncertainty)."),
    _OUT(["--uncertainty"], is_flag=True,
         help="Also write the per-pixel uncertainty: OUT/uncertainty/NAME.png (metres * 256, 0 = none), in the bag "
         "(--bag-out) and the Rerun recording, and in the viewer (--report)."),
    _OUT(["--max-uncertainty"], type=MaxUncertainty(), default=None,
         help="Point clouds (--ply, bird's-eye view, --bag-out, --rerun, --live) leave out pixels whose uncertainty "
         "exceeds METRES, or PERCENT% of their depth; depth maps stay dense."),
    _OUT(["--panel"], is_flag=True, help="Also write the per-branch panel (with --kitti-raw: a bird's-eye view)."),
    _OUT(["--ply"], is_flag=True, help="With --kitti-raw or --bag: also write a binary PLY point cloud."),
    _OUT(["--max-depth"], type=DEPTH_M, default=80.0, show_default=True,
         help="PLY / bird's-eye view: drop deeper pixels, m."),
    _OUT(["--top-crop"], type=PIXELS, default=0, show_default=True,
         help="PLY / bird's-eye view: drop the top N rows (sky)."),
    _OUT(["--report"], is_flag=True, help="Also write viewer.html: hover depths, layers, 3D view (with --K)."),
    _OUT(["--bag-out"], type=click.Path(path_type=Path), default=None,
         help="Also write a ROS 2 bag (MCAP; ROS 1 for .bag): depth 32FC1, coloured cloud, CameraInfo."),
    _OUT(["--rerun", "rerun_file"], type=click.Path(dir_okay=False, path_type=Path), default=None,
         help="Also write a Rerun recording FILE.rrd.  [extra: rerun]"),
    _OUT(["--rerun-spawn"], is_flag=True, help="Stream the frames to a spawned Rerun viewer."),
    _OUT(["--rerun-serve"], is_flag=False, flag_value=RERUN_SERVE, default=None, type=Address(),
         metavar="[[HOST:]PORT]",
         help=f"Serve the frames to Rerun viewers as they are completed, on [HOST:]PORT (alone: {RERUN_SERVE}; "
         "a HOST other than this machine's also serves the web viewer).  [extra: rerun]"),
    _OUT(["--live"], default=None, type=Address(),
         help="Serve the frames as they are completed over the Foxglove WebSocket protocol (HOST: 127.0.0.1 unless "
         "given).  [extra: live]"),
    _OUT(["--overwrite"], is_flag=True, help="Replace existing outputs."),
    _OUT(["--resume"], is_flag=False, flag_value="", default=None, metavar="[OUT]",
         help="Continue the killed or failed run in OUT (or --out): keep its completed frames, do the rest."),
    _RUN(["--on-error"], type=click.Choice(["skip", "stop"]), default=None,
         help="A frame that cannot be completed: skip it (named, counted; the default for several frames) or stop "
         "the run (the default for one frame; the frames done are kept)."),
    _RUN(["--stream"], is_flag=True,
         help="Read, project and segment the next frames in a background thread while one is completed."),
    _RUN(["--realtime"], is_flag=True,
         help="Replay at the recorded rate: frames that come while the completer is busy are dropped."),
    _RUN(["--speed"], type=SPEED, default=None, help="With --realtime: replay this many times faster (0.01-1000)."),
)  # fmt: skip

_F = TypeVar("_F", bound=Callable[..., object])


def output_options(f: _F) -> _F:
    """The output and run options of ``predict`` (read back with ``values_of(Outputs | RunOptions, params)``)."""
    return with_options(OUTPUT_OPTIONS)(f)


def _recordings() -> str:
    """The inputs that are a recording of a camera and a LiDAR, as options: ``--kitti-raw or --bag``."""
    return or_list([k.flag for k in INPUTS if k.recording])


@dataclass(frozen=True)
class Outputs:
    """The output options' values: files per frame, the run-wide outputs and the output folder's rules."""

    out: Path | None
    npy: bool
    uncertainty: bool
    max_uncertainty: str | None
    panel: bool
    ply: bool
    max_depth: float
    top_crop: int
    report: bool
    bag_out: Path | None
    rerun_file: Path | None
    rerun_spawn: bool
    rerun_serve: str | None
    live: str | None
    overwrite: bool
    resume: str | None

    @property
    def replayed(self) -> bool:
        """A bag or a Rerun recording or viewer: outputs a resumed run rebuilds from the kept frames."""
        served = self.rerun_serve is not None
        return self.bag_out is not None or self.rerun_file is not None or self.rerun_spawn or served

    @property
    def robot(self) -> bool:
        """Any robot output (a bag, Rerun, the live server): each needs the camera's intrinsics."""
        return self.replayed or self.live is not None

    @property
    def limit(self) -> UncertaintyLimit | None:
        from semattnet.inference.uncertainty import UncertaintyLimit

        return None if self.max_uncertainty is None else UncertaintyLimit.parse(self.max_uncertainty)

    def folder(self) -> tuple[Path, bool]:
        """``--out OUT [--resume]`` or ``--resume OUT``: the output folder and whether to resume."""
        resume, out = self.resume, self.out
        if resume and out is not None and Path(resume).resolve() != out.resolve():
            raise click.UsageError(f"--resume {resume} and --out {out} name two folders; give one")
        if resume:
            return Path(resume), True
        if out is None:
            raise click.UsageError("Missing option '--out'.")
        return out, resume is not None

    def check(self, chosen: ChosenInput) -> tuple[Path, bool]:
        """The outputs agree with each other and with the chosen input (usage errors, before any work); returns
        :meth:`folder`."""
        out, resuming = self.folder()
        kind = chosen.kind
        if self.ply and not kind.recording:
            raise click.UsageError(f"--ply needs {_recordings()}")
        require_with("--report, --bag-out, --rerun or --live", self.report or self.robot, "intrinsics")
        if self.report and not kind.report:
            viewable = or_list([k.usage for k in INPUTS if k.report])
            raise click.UsageError(f"--report needs {viewable} (not yet {kind.flag})")
        if self.robot and not chosen.values.has_intrinsics():
            raise click.UsageError(f"--bag-out, --rerun and --live need the intrinsics: {_recordings()}, or --K")
        clouds = self.ply or (self.panel and kind.recording) or self.robot
        require_with("--ply, --panel (with --kitti-raw or --bag), --bag-out, --rerun or --live", clouds,
                     "max_uncertainty")  # fmt: skip
        if self.max_uncertainty is not None and self.replayed and not self.uncertainty:
            raise click.UsageError("--max-uncertainty with --bag-out or --rerun needs --uncertainty (a resumed run "
                                   "rebuilds the kept frames' clouds from OUT/uncertainty/)")  # fmt: skip
        if resuming and self.overwrite:
            raise click.UsageError("give --resume or --overwrite, not both")
        return out, resuming

    def sinks(self, timer: StageTimes) -> list[Sink]:
        """The sinks the options ask for: the files per frame, ``latency.json`` and, as asked, the bag, the Rerun
        recording or viewer and the live server (their clouds without the pixels above ``--max-uncertainty``)."""
        from semattnet.inference.sinks import LatencySink, default_sinks
        from semattnet.robotics.sinks import BagSink, RerunSink

        limit, depth, unc = self.limit, self.max_depth, self.uncertainty
        sinks = default_sinks(self.npy, self.panel, self.ply, depth, self.top_crop, unc, limit)
        sinks.append(LatencySink(timer=timer))
        if self.bag_out is not None:
            sinks.append(BagSink(target=self.bag_out, max_depth=depth, uncertainty=unc, max_uncertainty=limit))
        if self.rerun_file is not None or self.rerun_spawn or self.rerun_serve is not None:
            rerun = RerunSink(target=self.rerun_file, spawn=self.rerun_spawn, serve=self.rerun_serve, max_depth=depth,
                              log=click.echo, uncertainty=unc, max_uncertainty=limit)  # fmt: skip
            sinks.append(rerun)
        if self.live is not None:
            from semattnet.robotics.live import LiveSink

            sinks.append(LiveSink(address=self.live, max_depth=depth, log=click.echo, max_uncertainty=limit))
        return sinks


@dataclass(frozen=True)
class RunOptions:
    """How the frames are run: a faulty frame, reading ahead, a real-time replay."""

    on_error: str | None
    stream: bool
    realtime: bool
    speed: float | None

    def check(self, chosen: ChosenInput) -> None:
        if self.speed is not None and not self.realtime:
            raise click.UsageError("--speed needs --realtime")
        if self.realtime and not chosen.kind.recording:
            raise click.UsageError(f"--realtime replays a recording: it needs {_recordings()}")

    @property
    def rate(self) -> float | None:
        """The replay's speed factor (None: not in real time)."""
        return (self.speed or 1.0) if self.realtime else None

    @property
    def prefetch(self) -> int:
        """Frames read ahead in a background thread."""
        return 2 if self.stream else 0
