"""The ``semattnet`` command line: a thin layer over the library."""

from __future__ import annotations

import json
from pathlib import Path

import click

from . import __version__


def _size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected HxW, e.g. 96x320; got {text!r}") from None
    return h, w


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="semattnet")
def main() -> None:
    """SemAttNet depth completion: models, checkpoints and demos."""


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default="semattnet-demo",
    show_default=True,
    help="Folder for the pictures and metrics.",
)
@click.option("--size", default="96x320", show_default=True, help="Scene size HxW (multiples of 32).")
@click.option("--width", default=0.125, show_default=True, help="Model width multiplier (1.0 = paper).")
@click.option("--steps", default=60, show_default=True, help="Training steps.")
@click.option("--seed", default=0, show_default=True)
@click.option("--device", default="auto", show_default=True, help="auto, cpu or cuda[:N].")
def demo(out_dir: Path, size: str, width: float, steps: int, seed: int, device: str) -> None:
    """Train a small SemAttNet on generated scenes and complete a held-out frame (no download)."""
    from .demo import run_demo

    run_demo(out_dir, size=_size(size), width=width, steps=steps, seed=seed, device=device, log=click.echo)


@main.command()
@click.option("--params/--no-params", default=False, help="Also build each model to count its parameters.")
def models(params: bool) -> None:
    """List the registered models (paper model and Table 2 ablations)."""
    from .registry import MODELS, build_model

    for name, (description, _) in MODELS.items():
        count = f"{sum(p.numel() for p in build_model(name).parameters()):>13,d}  " if params else ""
        click.echo(f"{name:20s} {count}{description}")


@main.command()
@click.argument("checkpoint", type=click.Path(exists=True, dir_okay=False, path_type=Path))
def info(checkpoint: Path) -> None:
    """Show what a checkpoint holds (never runs code from it)."""
    from .checkpoint import config_from_state_dict, load_checkpoint

    ckpt = _load_or_exit(checkpoint, load_checkpoint)
    cfg = ckpt.config or config_from_state_dict(ckpt.state_dict)
    n = sum(v.numel() for k, v in ckpt.state_dict.items() if not k.endswith("num_batches_tracked"))
    click.echo(f"file:        {ckpt.path}  ({ckpt.format})")
    click.echo(f"entries:     {len(ckpt.state_dict)} tensors, {n:,d} values")
    click.echo(f"model:       {json.dumps(cfg.to_dict())}")
    if ckpt.epoch is not None:
        click.echo(f"epoch:       {ckpt.epoch}")
    if ckpt.best_result is not None:
        click.echo(f"best_result: {ckpt.best_result!r}")
    if ckpt.neutralised:
        click.echo(f"neutralised: {', '.join(sorted(ckpt.neutralised))} (loaded as inert records)")


@main.command()
@click.argument("src", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("dst", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--overwrite", is_flag=True, help="Replace DST if it exists.")
def convert(src: Path, dst: Path, overwrite: bool) -> None:
    """Convert a checkpoint (authors' .pth.tar, state dict) to weights-only safetensors."""
    from .checkpoint import load_checkpoint, save_safetensors

    if dst.exists() and not overwrite:
        raise click.ClickException(f"{dst} exists; pass --overwrite to replace it")
    ckpt = _load_or_exit(src, load_checkpoint)
    save_safetensors(ckpt, dst)
    click.echo(f"wrote {dst} ({len(ckpt.state_dict)} tensors, {dst.stat().st_size / 2**20:.1f} MiB)")


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the KITTI-layout tree.",
)
@click.option("--frames", default=100, show_default=True, help="Training frames.")
@click.option(
    "--eval-frames", type=int, default=None, help="Frames for each of val, val_select, test [frames/5, >= 2]."
)
@click.option("--size", default="352x1216", show_default=True, help="Frame size HxW.")
@click.option("--seed", default=0, show_default=True)
@click.option("--workers", type=int, default=None, help="Processes [all cores]; the output does not depend on it.")
@click.option("--overwrite", is_flag=True, help="Write into a non-empty folder, replacing a previous tree.")
def synth(out_dir: Path, frames: int, eval_frames: int | None, size: str, seed: int, workers: int | None,
          overwrite: bool) -> None:  # fmt: skip
    """Generate synthetic KITTI-like scenes in the KITTI depth completion layout."""
    from .data.synthetic_tree import write_synthetic_kitti

    try:
        manifest = write_synthetic_kitti(out_dir, frames, _size(size), seed, eval_frames, workers, overwrite)
    except FileExistsError as exc:
        raise click.ClickException(str(exc)) from None
    counts = ", ".join(f"{k} {v}" for k, v in manifest["counts"].items())
    click.echo(f"wrote {out_dir}: {counts} (manifest: {out_dir / 'scenes.json'})")


@main.command(context_settings={"show_default": True})
@click.option("--stage", type=click.Choice(["backbone", "refine-init", "full"]), default="backbone")
@click.option(
    "--data", "data_root", type=click.Path(file_okay=False), help="KITTI depth completion root (or a synth tree)."
)
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Run folder [runs/<stage>].")
@click.option("--init", type=click.Path(dir_okay=False), default=None, help="Checkpoint of the previous stage.")
@click.option(
    "--config",
    "config_file",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="A config.json to start from (options and --set override it).",
)
@click.option("--resume", is_flag=True, help="Continue the run in --out exactly where it stopped.")
@click.option("--epochs", type=int, default=None, help="[stage default: 60 / 5 / 95]")
@click.option("--batch-size", type=int, default=None, help="Per process [stage default: 8 / 8 / 16].")
@click.option("--lr", type=float, default=None, help="[stage default]")
@click.option("--width", type=float, default=None, help="Model width multiplier [1.0].")
@click.option("--crop", default=None, help="Training crop HxW [352x1216].")
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default=None)
@click.option("--device", default=None, help="auto, cpu or cuda.")
@click.option("--workers", type=int, default=None, help="Data loading processes [4].")
@click.option("--max-steps", type=int, default=None, help="Stop after N steps in total.")
@click.option(
    "--set", "overrides", multiple=True, metavar="KEY=VALUE", help="Any TrainConfig field, e.g. --set val_every=2."
)
def train(stage: str, data_root: str | None, out: str | None, init: str | None, config_file: str | None, resume: bool,
          epochs: int | None, batch_size: int | None, lr: float | None, width: float | None, crop: str | None,
          amp: str | None, device: str | None, workers: int | None, max_steps: int | None,
          overrides: tuple[str, ...]) -> None:  # fmt: skip
    """Train one stage of the paper's recipe (works under torchrun for DDP)."""
    from .checkpoint import CheckpointError
    from .data.io import DataError
    from .engine import train as run_training
    from .train_config import TrainConfig

    try:
        if resume:
            if not out:
                raise click.UsageError("--resume needs --out (the run folder)")
            cfg = TrainConfig(out=out)
        else:
            base = TrainConfig.load(config_file).to_dict() if config_file else {"stage": stage}
            given = {"stage": stage if not config_file else base["stage"], "data": data_root, "init": init,
                     "epochs": epochs, "batch_size": batch_size, "lr": lr, "width": width, "amp": amp,
                     "device": device, "workers": workers, "max_steps": max_steps,
                     "crop": list(_size(crop)) if crop else None}  # fmt: skip
            base.update({k: v for k, v in given.items() if v is not None})
            base["out"] = out or base.get("out") or f"runs/{base['stage']}"
            if "crop" in base and crop and not config_file:
                base["random_crop_height"] = None  # re-derive from the new crop
            cfg = TrainConfig.from_dict(base).with_overrides(list(overrides))
        result = run_training(cfg, resume=resume, log=click.echo)
    except (CheckpointError, DataError, ValueError) as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(f"done: epoch {result['epoch']}, step {result['step']}, best RMSE {result['best_rmse_mm']:.1f} mm")


@main.group()
def data() -> None:
    """Data sets: validation of KITTI / synthetic trees."""


@data.command("check")
@click.argument("roots", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--raw-root",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="KITTI raw data [ROOT/kitti_raw or ROOT/raw].",
)
@click.option(
    "--semantic-root",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Semantic maps [ROOT/semantic or ROOT/semantics].",
)
@click.option("--sample", type=int, default=None, help="Decode at most N frames per split [all].")
def data_check(roots: tuple[Path, ...], raw_root: Path | None, semantic_root: Path | None, sample: int | None) -> None:
    """Check KITTI depth completion trees; exits 1 if anything is missing, unpaired or broken."""
    from .data.check import check_tree

    bad = 0
    for root in roots:
        reports = check_tree(root, raw_root, semantic_root, sample)
        click.echo(f"{root}:")
        if not reports:
            click.echo("  no KITTI depth completion files found")
            bad += 1
        for rep in reports:
            click.echo("  " + rep.summary())
            for problem in rep.problems[:20]:
                click.echo(f"    - {problem}")
            if len(rep.problems) > 20:
                click.echo(f"    ... {len(rep.problems) - 20} more")
            bad += len(rep.problems)
    if bad:
        raise SystemExit(1)


def _load_or_exit(path: Path, loader):  # type: ignore[no-untyped-def]
    """Run ``loader(path)``; a bad or unsafe checkpoint becomes a one-line CLI error."""
    from .checkpoint import CheckpointError, UnsafeCheckpointError

    try:
        return loader(path)
    except (CheckpointError, UnsafeCheckpointError) as exc:
        raise click.ClickException(str(exc)) from None


if __name__ == "__main__":
    main()
