"""``semattnet train``: one stage of the paper's training recipe."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import click

from semattnet.cli._dataset import dataset_option
from semattnet.cli._group import main
from semattnet.cli._model import device_option
from semattnet.cli._options import (
    BATCH_SIZE,
    COUNT,
    LEARNING_RATE,
    POSITIVE_INT,
    SIZE,
    WEIGHTS_SPEC,
    WIDTH,
    WORKERS,
    one_value,
    parse_size,
    resolve_option,
)

if TYPE_CHECKING:
    from semattnet.training.config import TrainConfig

#: What a command-line option of ``train`` parses to.
OptionValue = str | int | float | bool | None
#: The options that are config fields of the same name.
_FIELDS = ("epochs", "batch_size", "lr", "model", "width", "amp", "device", "workers", "max_steps", "segment")


def _model_name(ctx: click.Context, param: click.Parameter, name: str | None) -> str | None:
    """``--model``: a registered name (or alias), else a one-line error listing them."""
    if name is None:
        return None
    from semattnet._errors import InputError
    from semattnet.models.registry import UnknownModelError, resolve_model_name

    try:
        return resolve_model_name(name)
    except UnknownModelError as exc:
        raise InputError(f"--model: {exc}") from None


@main.command(context_settings={"show_default": True})
@click.option("--stage", type=click.Choice(["backbone", "refine-init", "full"]), default="backbone")
@click.option(
    "--data", "data_root", type=click.Path(file_okay=False), help="KITTI depth completion root (or a synth tree)."
)
@dataset_option("The dataset (its reader, augmentation, metrics, palette); not kitti-dc: its recipe is the start.")
@click.option(
    "--segment",
    "segment",
    default=None,
    metavar="SPEC",
    help="nyuv2 / void: semantic maps from this segmenter (e.g. hf:indoor; see `semattnet segment`), "
    "segmented once into a cache folder and reused.",
)
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Run folder [runs/<stage>].")
@click.option(
    "--init",
    "--init-weights",
    "init",
    multiple=True,
    callback=one_value(WEIGHTS_SPEC),
    metavar="NAME|PATH|URL",
    help="Weights to start from: the previous stage's checkpoint, or released "
    "weights by name or URL (semattnet weights list). --init-weights is an alias.",
)
@click.option(
    "--config",
    "config_file",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="A config.json to start from (options and --set override it).",
)
@click.option("--resume", is_flag=True, help="Continue the run in --out exactly where it stopped.")
@click.option("--overwrite", is_flag=True, help="Start over in a run folder that already holds a run.")
@click.option("--epochs", type=POSITIVE_INT, default=None, help="[stage default: 60 / 5 / 95]")
@click.option("--batch-size", type=BATCH_SIZE, default=None, help="Per process [stage default: 8 / 8 / 16].")
@click.option("--lr", type=LEARNING_RATE, default=None, help="[stage default]")
@click.option(
    "--model",
    "model",
    default=None,
    metavar="NAME",
    callback=_model_name,
    help="A registered model (semattnet models), e.g. semattnet_rt_s [semattnet].",
)
@click.option("--width", type=WIDTH, default=None, help="Model width multiplier [1.0].")
@click.option("--crop", type=SIZE, default=None, help="Training crop HxW [352x1216].")
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default=None)
@device_option(default=None, help="Where training runs: auto, cpu, cuda[:N] or mps [the config's].")
@click.option("--workers", type=WORKERS, default=None, help="Data loading processes [4].")
@click.option("--max-steps", type=COUNT, default=None, help="Stop after N steps in total.")
@click.option(
    "--activation-checkpointing",
    is_flag=True,
    default=None,
    help="Recompute each branch in the backward pass: less memory, one more forward.",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="KEY=VALUE",
    help="A TrainConfig field, e.g. --set val_every=2.",
)
def train(resume: bool, overwrite: bool, overrides: tuple[str, ...], **options: OptionValue) -> None:
    """Train one stage of the paper's recipe (works under torchrun for DDP)."""
    from semattnet.training.trainer import train as run_training

    cfg = _train_config(resume, overrides, options)
    result = run_training(cfg, resume=resume, overwrite=overwrite, log=click.echo)
    click.echo(f"done: epoch {result['epoch']}, step {result['step']}, best RMSE {result['best_rmse_mm']:.1f} mm")


def _train_config(resume: bool, overrides: tuple[str, ...], o: Mapping[str, OptionValue]) -> TrainConfig:
    """The run's config from the options: a resumed run's own (in ``--out``), else ``--config`` or the stage's
    recipe, the options given over it, then ``--set``."""
    from semattnet.training.config import TrainConfig

    out, init, crop, config_file = (o["out"], o["init"], o["crop"], o["config_file"])
    if init is not None:  # a name or URL goes through the download cache; a local file stays as it is
        init = str(resolve_option(str(init), "--init").file)
    if resume:
        if not out:
            raise click.UsageError("--resume needs --out (the run folder)")
        if o["model"] is not None:
            raise click.UsageError("--model: a resumed run keeps its model (the one in its config.json)")
        return TrainConfig(out=str(out))
    from semattnet.data.datasets import get_dataset

    dataset, stage = str(o["dataset"]), o["stage"]
    recipe = get_dataset(dataset).recipe if dataset != "kitti-dc" else {}
    base = TrainConfig.load(str(config_file)).to_dict() if config_file else {"stage": stage, **recipe}
    if not config_file or dataset != "kitti-dc":
        base["dataset"] = dataset
    given = {name: o[name] for name in _FIELDS} | {
        "stage": stage if not config_file else base["stage"],
        "data": o["data_root"],
        "init": init,
        "activation_checkpointing": o["activation_checkpointing"] or None,
        "crop": list(parse_size(str(crop))) if crop else None,
    }
    base.update({k: v for k, v in given.items() if v is not None})
    base["out"] = out or base.get("out") or f"runs/{base['stage']}"
    if "crop" in base and crop and not config_file:
        base["random_crop_height"] = None  # re-derive from the new crop
    return TrainConfig.from_dict(base).with_overrides(list(overrides))
