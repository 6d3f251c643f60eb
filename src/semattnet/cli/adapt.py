"""``semattnet adapt``: fine-tune weights on your own frames with no ground truth (:mod:`semattnet.training.adapt`).

Its inputs are ``predict``'s, generated from the source registry (:mod:`semattnet.cli._inputs`): a folder of
frames, a KITTI raw drive, a ROS bag, a dataset split.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from semattnet.cli._group import main
from semattnet.cli._inputs import MAP_OPTIONS, choose_input, input_params
from semattnet.cli._model import device_option
from semattnet.cli._options import (
    BATCH_SIZE,
    COUNT,
    LEARNING_RATE,
    MODEL,
    NONNEGATIVE_FLOAT,
    POSITIVE_INT,
    parse_size,
    weights_option,
)
from semattnet.cli._params import GeneratedCommand, rehelp, section, values_of, with_options

if TYPE_CHECKING:
    from semattnet.training.adapt import AdaptConfig

#: ``adapt``'s own options, listed under "Adaptation" in ``--help``.
_OPTION = section("Adaptation")

#: The options a resumed run takes from its state, by parameter: the field of the run's configuration each sets.
#: Given with ``--resume``, each must agree with the run's (``semattnet.training.adapt.resume.resumed_config``).
_RUN_FIELDS = {
    "weights": "weights",
    "steps": "steps",
    "batch_size": "batch_size",
    "lr": "lr",
    "crop": "crop",
    "losses": "losses",
    "hide": "hide",
    "w_kept": "w_kept",
    "w_photometric": "w_photometric",
    "w_smooth": "w_smooth",
    "no_automask": "automask",
    "train_bn": "freeze_bn",
    "amp": "amp",
    "seed": "seed",
    "gt_every": "gt_every",
    "gt_frames": "gt_frames",
    "save_every": "save_every",
    "on_error": "on_error",
}


def _given(ctx: click.Context) -> list[str]:
    """The fields of the run's configuration whose options the command line gave (not left at their defaults)."""
    from click.core import ParameterSource

    defaults = (None, ParameterSource.DEFAULT, ParameterSource.DEFAULT_MAP)
    return [field for name, field in _RUN_FIELDS.items() if ctx.get_parameter_source(name) not in defaults]


def _hide(text: str) -> tuple[float, float]:
    """``--hide``: a share ``0.25`` or a range ``0.2..0.3`` (a usage error of ``--hide`` if not)."""
    try:
        low, _, high = text.partition("..")
        values = (float(low), float(high or low))
    except ValueError:
        raise click.BadParameter(
            f"expected a share like 0.25 or a range like 0.2..0.3, got {text!r}", param_hint="--hide"
        ) from None
    if not 0 < values[0] <= values[1] < 1:
        raise click.BadParameter(f"the share must lie in (0, 1), low <= high; got {text!r}", param_hint="--hide")
    return values


ADAPT_OPTIONS = (
    _OPTION(
        ["--out"],
        required=True,
        type=click.Path(file_okay=False, path_type=Path),
        help="The run folder: adapted.safetensors, checkpoints/last.pt (to resume), log.json.",
    ),
    _OPTION(["--steps"], type=POSITIVE_INT, default=1000, show_default=True, help="Optimiser steps in total."),
    _OPTION(["--batch-size"], type=BATCH_SIZE, default=2, show_default=True, help="Random crops per step."),
    _OPTION(["--lr"], type=LEARNING_RATE, default=1e-4, show_default=True, help="Adam's rate, cosine to 0."),
    _OPTION(
        ["--crop"],
        default="256x512",
        show_default=True,
        help="Crop HxW, multiples of 32 (smaller frames: their size, rounded down).",
    ),
    _OPTION(
        ["--loss", "losses"],
        default="sparse,photometric,smoothness",
        show_default=True,
        help="The losses, comma-separated: sparse (hidden LiDAR points), photometric (the frames' other views: "
        "KITTI raw's stereo partner and neighbours, a bag's neighbours posed by /tf), smoothness.",
    ),
    _OPTION(
        ["--odom-frame"],
        default=None,
        help="With --bag: the fixed frame of /tf that poses the neighbouring frames [odom if /tf has it, else the "
        "root of /tf's tree].",
    ),
    _OPTION(
        ["--hide"],
        default="0.2..0.3",
        show_default=True,
        help="The share of LiDAR points hidden from the input each step: 0.25, or a range drawn from.",
    ),
    _OPTION(
        ["--w-kept"],
        type=NONNEGATIVE_FLOAT,
        default=0.5,
        show_default=True,
        help="Weight of the sparse loss at the kept (input) points; the hidden ones weigh 1.",
    ),
    _OPTION(
        ["--w-photometric"],
        type=NONNEGATIVE_FLOAT,
        default=1.0,
        show_default=True,
        help="Weight of the photometric loss.",
    ),
    _OPTION(
        ["--w-smooth"], type=NONNEGATIVE_FLOAT, default=1e-3, show_default=True, help="Weight of the smoothness loss."
    ),
    _OPTION(["--no-automask"], is_flag=True, help="Keep every pixel in the photometric loss (no auto-masking)."),
    _OPTION(
        ["--train-bn"],
        is_flag=True,
        help="Let BatchNorm update its running statistics (default: frozen); under torchrun as SyncBatchNorm, "
        "which needs CUDA.",
    ),
    _OPTION(
        ["--amp"],
        type=click.Choice(["none", "bf16", "fp16"]),
        default="none",
        show_default=True,
        help="Autocast, as train's: fp16 needs CUDA, bf16 on a CPU needs native bfloat16.",
    ),
    _OPTION(["--seed"], type=COUNT, default=0, show_default=True, help="Frames, crops and hidden points follow it."),
    _OPTION(
        ["--gt-every"],
        type=COUNT,
        default=0,
        show_default=True,
        help="Where frames have ground truth: the KITTI metrics on held-out ones every N steps (0: never).",
    ),
    _OPTION(
        ["--gt-frames"],
        type=POSITIVE_INT,
        default=1,
        show_default=True,
        help="With --gt-every: frames with ground truth held out of training for the metric.",
    ),
    _OPTION(
        ["--save-every"],
        type=POSITIVE_INT,
        default=100,
        show_default=True,
        help="Write the resumable state every N steps (and at the end).",
    ),
    _OPTION(
        ["--on-error"],
        type=click.Choice(["skip", "stop"]),
        default=None,
        help="A frame that cannot be read: skip it (one line; the default for several frames) or stop.",
    ),
    _OPTION(["--resume"], is_flag=True, help="Continue the run in --out exactly where it stopped."),
    _OPTION(["--overwrite"], is_flag=True, help="Start over in a folder that holds a run."),
)


@dataclass(frozen=True)
class AdaptOptions:
    """The parsed values of ``adapt``'s own options (and ``--weights``, ``--device``)."""

    weights: str | None
    device: str
    out: Path
    steps: int
    batch_size: int
    lr: float
    crop: str
    losses: str
    odom_frame: str | None
    hide: str
    w_kept: float
    w_photometric: float
    w_smooth: float
    no_automask: bool
    train_bn: bool
    amp: str
    seed: int
    gt_every: int
    gt_frames: int
    save_every: int
    on_error: str | None
    resume: bool
    overwrite: bool

    def config(self, frames: int) -> AdaptConfig:
        """The run's configuration (usage errors naming the option); ``frames``: how many the source has (the
        default of ``--on-error``, as ``predict``'s: skip for several, stop for one)."""
        from semattnet.inference.options import RunOptions
        from semattnet.training.adapt import LOSS_TERMS, AdaptConfig

        crop = parse_size(self.crop, "--crop")
        if any(side % 32 for side in crop):
            raise click.BadParameter(f"{crop[0]}x{crop[1]}: both sides must be multiples of 32", param_hint="--crop")
        losses = tuple(t.strip() for t in self.losses.split(",") if t.strip())
        if not losses or any(t not in LOSS_TERMS for t in losses) or len(set(losses)) != len(losses):
            raise click.BadParameter(
                f"expected distinct names of {', '.join(LOSS_TERMS)}, got {self.losses!r}", param_hint="--loss"
            )
        return AdaptConfig(
            weights=self.weights or "",
            out=str(self.out),
            steps=self.steps,
            batch_size=self.batch_size,
            lr=self.lr,
            crop=crop,
            losses=losses,
            hide=_hide(self.hide),
            w_kept=self.w_kept,
            w_photometric=self.w_photometric,
            w_smooth=self.w_smooth,
            automask=not self.no_automask,
            freeze_bn=not self.train_bn,
            amp=self.amp,
            device=self.device,
            seed=self.seed,
            gt_every=self.gt_every,
            gt_frames=self.gt_frames,
            save_every=self.save_every,
            on_error=RunOptions(on_error=self.on_error).policy(frames),
        )


def _input_params() -> list[click.Parameter]:
    """``predict``'s input options, with the help of those that name outputs ``adapt`` lacks said for ``adapt``."""
    return rehelp(
        input_params(),
        {"intrinsics": "The camera's intrinsics of the --rgb / --sparse frames ('kitti': KITTI's camera 02)."},
    )


@main.command(cls=GeneratedCommand, generated=[("", _input_params)])
@with_options(MAP_OPTIONS)
@weights_option
@device_option(help="Where training runs: auto, cpu, cuda[:N].", cls=section(MODEL))
@with_options(ADAPT_OPTIONS)
def adapt(**params: object) -> None:
    """Fine-tune weights on your own frames with no ground truth: hidden LiDAR points, photometric consistency with
    the frames' other views (a stereo partner, neighbouring frames) and edge-aware smoothness (docs: guides/adapt.md).

    Reads every input `predict` reads. Writes OUT/adapted.safetensors (for `predict --weights`),
    OUT/checkpoints/last.pt (--resume) and OUT/log.json. Frames that cannot be read are skipped and counted
    (exit status 3 when some were)."""
    from semattnet._utils.distributed import launch_rank
    from semattnet.training.adapt import adapt as run_adaptation

    ctx = click.get_current_context()
    chosen = choose_input(ctx)
    listing = chosen.values.listing()
    if listing is not None:  # --list-topics
        click.echo(listing)
        return
    options = values_of(AdaptOptions, params)
    if options.weights is None and not options.resume:
        raise click.UsageError("--weights is required (the weights to adapt), unless --resume")
    source, maps = chosen.open(options.device)
    if options.odom_frame is not None:
        if not hasattr(source, "odom_frame"):
            raise click.UsageError("--odom-frame poses a bag's neighbouring frames: it needs --bag")
        source.odom_frame = options.odom_frame
    cfg = options.config(len(source.names))
    asked = _given(ctx) if options.resume else ()
    result = run_adaptation(
        cfg, source, maps, resume=options.resume, overwrite=options.overwrite, log=click.echo, asked=asked
    )
    if launch_rank() == 0:  # under torchrun, rank 0 alone reports
        skipped = f", {len(result.skipped)} frame(s) skipped" if result.skipped else ""
        metric = f", held-out RMSE {result.metrics['rmse_mm']:.0f} mm" if result.metrics else ""
        click.echo(
            f"done: step {result.step} on {result.frames} frame(s){skipped}{metric}, "
            f"{result.seconds_per_step:.2f} s/step; weights: {result.weights}"
        )
    if result.skipped:
        ctx.exit(3)
