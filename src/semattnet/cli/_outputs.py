"""What ``predict`` writes and how it runs: the output and run options, their checks and the sinks they ask for.

The sinks are made from the sink registry (:data:`semattnet.inference.sinks.SINKS`): each entry's
:class:`~semattnet.inference.sinks.SinkOptions` declares its own options (listed under "Outputs") and makes its
sinks from them and the shared output options here (:class:`~semattnet.inference.sinks.OutputSettings`). The
rules that are about combinations (an output that needs what only some inputs give: intrinsics, a LiDAR
recording, frames the viewer can show) are written here once, against the declared facts of the chosen
:class:`~semattnet.cli._inputs.InputKind` and of the sinks asked for, so they name both from the tables.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import click

from semattnet.cli._inputs import ChosenInput, field_options, input_kinds, or_list
from semattnet.cli._options import DEPTH_M, PIXELS, SPEED, require_with
from semattnet.cli._params import section, values_of, with_options
from semattnet.inference.options import OutputSpec
from semattnet.inference.options import RunOptions as LoopOptions
from semattnet.inference.sinks import SINKS, SinkOptions

if TYPE_CHECKING:
    from semattnet.inference.sinks import Sink
    from semattnet.inference.timing import StageTimes
    from semattnet.inference.uncertainty import UncertaintyLimit

__all__ = ["OUTPUTS", "RUN", "AskedSinks", "Outputs", "RunCommandOptions", "output_options", "sink_params"]

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


_OUT, _RUN = section(OUTPUTS), section(RUN)

#: The output options, then the run options, in the order of ``predict --help``.
OUTPUT_OPTIONS = (
    _OUT(["--out"], default=None, type=click.Path(file_okay=False, path_type=Path), help="Output folder [required]."),
    _OUT(["--npy"], is_flag=True, help="Also write float32 .npy depth (and uncertainty, with --uncertainty)."),
    _OUT(
        ["--uncertainty"],
        is_flag=True,
        help="Also write the per-pixel uncertainty: OUT/uncertainty/NAME.png (metres * 256, 0 = none), in the bag "
        "(--bag-out) and the Rerun recording, and in the viewer (--report).",
    ),
    _OUT(
        ["--max-uncertainty"],
        type=MaxUncertainty(),
        default=None,
        help="Point clouds (--ply, bird's-eye view, --bag-out, --rerun, --live) leave out pixels whose uncertainty "
        "exceeds METRES, or PERCENT% of their depth; depth maps stay dense.",
    ),
    _OUT(
        ["--max-depth"],
        type=DEPTH_M,
        default=80.0,
        show_default=True,
        help="PLY / bird's-eye view: drop deeper pixels, m.",
    ),
    _OUT(
        ["--top-crop"],
        type=PIXELS,
        default=0,
        show_default=True,
        help="PLY / bird's-eye view: drop the top N rows (sky).",
    ),
    _OUT(["--report"], is_flag=True, help="Also write viewer.html: hover depths, layers, 3D view (with --K)."),
    _OUT(["--overwrite"], is_flag=True, help="Replace existing outputs."),
    _OUT(
        ["--resume"],
        is_flag=False,
        flag_value="",
        default=None,
        metavar="[OUT]",
        help="Continue the killed or failed run in OUT (or --out): keep its completed frames, do the rest.",
    ),
    _RUN(
        ["--on-error"],
        type=click.Choice(["skip", "stop"]),
        default=None,
        help="A frame that cannot be completed: skip it (named, counted; the default for several frames) or stop "
        "the run (the default for one frame; the frames done are kept).",
    ),
    _RUN(
        ["--stream"],
        is_flag=True,
        help="Read, project and segment the next frames in a background thread while one is completed.",
    ),
    _RUN(
        ["--realtime"],
        is_flag=True,
        help="Replay at the recorded rate: frames that come while the completer is busy are dropped.",
    ),
    _RUN(["--speed"], type=SPEED, default=None, help="With --realtime: replay this many times faster (0.01-1000)."),
)

_F = TypeVar("_F", bound=Callable[..., object])


def output_options(f: _F) -> _F:
    """The shared output and run options of ``predict`` (read back with ``values_of(Outputs | RunCommandOptions,
    params)``); the sinks' own: :func:`sink_params`."""
    return with_options(OUTPUT_OPTIONS)(f)


_CACHE: dict[type, tuple[click.Option, ...]] = {}


def sink_params() -> list[click.Option]:
    """The options of every registered sink, in the registry's order, under "Outputs"."""
    for e in SINKS.values():
        if e.options is not None and e.options not in _CACHE:
            _CACHE[e.options] = field_options(e.options, OUTPUTS)
    return [o for e in SINKS.values() if e.options is not None for o in _CACHE[e.options]]


def _recordings() -> str:
    """The inputs that are a recording of a camera and a LiDAR, as options: ``--kitti-raw or --bag``."""
    return or_list([k.flag for k in input_kinds() if k.recording])


def _and_list(items: Sequence[str]) -> str:
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


@dataclass(frozen=True)
class AskedSinks:
    """The sinks' options as given: ``values`` (name -> the entry's :class:`SinkOptions`), and the facts the rules
    read, by the option naming each sink (its first)."""

    values: Mapping[str, SinkOptions]

    @classmethod
    def of(cls, params: Mapping[str, object]) -> AskedSinks:
        return cls({e.name: values_of(e.options, params) for e in SINKS.values() if e.options is not None})

    def flag(self, name: str) -> str:
        """The option naming sink ``name``: its first (``--bag-out``)."""
        first = fields(self.values[name])[0].name
        return next(o.opts[0] for o in sink_params() if o.name == first)

    def named(self, when: Callable[[str, SinkOptions], bool]) -> list[str]:
        """The flags of the sinks with options (asked or not) for which ``when(name, options)`` holds."""
        return [self.flag(n) for n, v in self.values.items() if fields(v) and when(n, v)]

    def any(self, when: Callable[[str, SinkOptions], bool]) -> bool:
        """Whether a sink asked for satisfies ``when``."""
        return any(v.asked() and when(n, v) for n, v in self.values.items())


def _replays(name: str, v: SinkOptions) -> bool:
    """A resumed run rebuilds it from the kept frames (the sink's :attr:`~semattnet.inference.sinks.Sink.replays`)."""
    return SINKS[name].cls.replays


@dataclass(frozen=True)
class Outputs:
    """The shared output options' values: files per frame, the clouds, the viewer and the output folder's rules."""

    out: Path | None
    npy: bool
    uncertainty: bool
    max_uncertainty: str | None
    max_depth: float
    top_crop: int
    report: bool
    overwrite: bool
    resume: str | None

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

    def check(self, chosen: ChosenInput, asked: AskedSinks) -> tuple[Path, bool]:
        """The outputs agree with each other and with the chosen input (usage errors, before any work); returns
        :meth:`folder`."""
        out, resuming = self.folder()
        kind = chosen.kind
        for flag in asked.named(lambda n, v: v.asked() and v.needs_recording and not kind.recording):
            raise click.UsageError(f"{flag} needs {_recordings()}")
        robots = asked.named(lambda n, v: v.needs_intrinsics)
        robot = asked.any(lambda n, v: v.needs_intrinsics)
        require_with(or_list(["--report", *robots]), self.report or robot, "intrinsics")
        if self.report and not kind.report:
            viewable = or_list([k.usage for k in input_kinds() if k.report])
            raise click.UsageError(f"--report needs {viewable} (not yet {kind.flag})")
        if robot and not chosen.values.has_intrinsics():
            raise click.UsageError(f"{_and_list(robots)} need the intrinsics: {_recordings()}, or --K")
        self._check_clouds(kind.recording, asked)
        if resuming and self.overwrite:
            raise click.UsageError("give --resume or --overwrite, not both")
        return out, resuming

    def _check_clouds(self, recording: bool, asked: AskedSinks) -> None:
        """``--max-uncertainty`` only with an output that draws clouds (and ``--uncertainty`` for a replayed one)."""
        label = {"always": "{}", "recording": f"{{}} (with {_recordings()})"}
        names = [label[v.clouds].format(asked.flag(n)) for n, v in asked.values.items() if v.clouds]
        clouds = asked.any(lambda n, v: v.clouds == "always" or (v.clouds == "recording" and recording))
        require_with(or_list(names), clouds, "max_uncertainty")
        if self.max_uncertainty is not None and asked.any(_replays) and not self.uncertainty:
            replayed = or_list(asked.named(_replays))
            raise click.UsageError(
                f"--max-uncertainty with {replayed} needs --uncertainty (a resumed run rebuilds "
                "the kept frames' clouds from OUT/uncertainty/)"
            )

    def spec(self, resuming: bool, identity: Mapping[str, object], inputs: Sequence[Path | None]) -> OutputSpec:
        """The library's :class:`~semattnet.inference.options.OutputSpec` of these options: ``resuming`` (from
        :meth:`folder`), the run's ``identity`` and the further ``inputs`` (the weights)."""
        return OutputSpec(self.overwrite, resuming, identity, tuple(inputs))

    def sinks(self, asked: AskedSinks, timer: StageTimes) -> list[Sink]:
        """The sinks of every registry entry, in its order, as its options and the shared ones ask: the files per
        frame, ``latency.json`` and the bag, the Rerun recording or viewer and the live server (their clouds
        without the pixels above ``--max-uncertainty``)."""
        from semattnet.inference.sinks import OutputSettings

        settings = OutputSettings(
            self.npy, self.uncertainty, self.limit, self.max_depth, self.top_crop, timer, click.echo
        )
        return [sink for values in asked.values.values() for sink in values.sinks(settings)]


@dataclass(frozen=True)
class RunCommandOptions:
    """How the frames are run: a faulty frame, reading ahead, a real-time replay."""

    on_error: str | None
    stream: bool
    realtime: bool
    speed: float | None

    def check(self, chosen: ChosenInput) -> None:
        """The run options agree with each other and with the chosen input (usage errors)."""
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

    def options(self) -> LoopOptions:
        """The library's :class:`~semattnet.inference.options.RunOptions` of these options."""
        return LoopOptions(self.on_error, self.prefetch, self.rate)
