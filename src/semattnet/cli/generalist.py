"""``semattnet train-generalist``: the generalist's recipe, one command from the synthetic world to packed weights."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._group import main
from semattnet.cli._options import BATCH_SIZE, COUNT, LEARNING_RATE, POSITIVE_INT


@main.command("train-generalist", context_settings={"show_default": True})
@click.option(
    "--model",
    type=click.Choice(
        [
            "semattnet_rt_generalist",
            "semattnet_rt_half_generalist",
            "semattnet_rt_l_generalist",
            "semattnet_generalist",
            "semattnet_half_generalist",
        ]
    ),
    default="semattnet_rt_generalist",
    help="The generalist to train: a real-time variant or the paper's model (half: its network at half resolution).",
)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True, help="The run's folder.")
@click.option(
    "--bank",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="The folder of world frames, written when missing and shared between runs [OUT/bank].",
)
@click.option("--frames", type=POSITIVE_INT, default=600, help="World frames in the bank.")
@click.option("--steps", type=POSITIVE_INT, default=1500, help="Optimisation steps.")
@click.option("--batch", type=BATCH_SIZE, default=8, help="Crops per step.")
@click.option("--crop", default="160x256", help="Crop HxW, multiples of 32.")
@click.option("--lr", type=LEARNING_RATE, default=2e-3, help="Adam's learning rate.")
@click.option("--init", default=None, metavar="NAME|PATH", help="Start from the plain network's weights.")
@click.option("--seed", type=COUNT, default=0, help="Seed of the crops and the initialisation.")
@click.option(
    "--calibration-frames", type=POSITIVE_INT, default=24, help="Held-out world frames the uncertainty is fitted on."
)
@click.option("--resume", is_flag=True, help="Go on from OUT/last.pt.")
def train_generalist_command(
    model: str,
    out: Path,
    bank: Path | None,
    frames: int,
    steps: int,
    batch: int,
    crop: str,
    lr: float,
    init: str | None,
    seed: int,
    calibration_frames: int,
    resume: bool,
) -> None:
    """Train a generalist on the synthetic world, calibrate its uncertainty, write OUT/MODEL.safetensors.gz."""
    from semattnet.cli._options import parse_size
    from semattnet.training.generalist import GeneralistTrainConfig, finish_generalist, train_generalist, write_bank

    bank = bank if bank is not None else out / "bank"
    write_bank(bank, frames, log=click.echo)
    cfg = GeneralistTrainConfig(
        model=model,
        bank=str(bank),
        out=str(out),
        steps=steps,
        batch=batch,
        crop=parse_size(crop, "--crop"),
        lr=lr,
        init=init,
        seed=seed,
    )
    trained = train_generalist(cfg, resume=resume, log=click.echo)
    path = finish_generalist(trained, cfg, calibration_frames, log=click.echo)
    click.echo(f"wrote {path}")
