"""The ``semattnet`` command line: a thin layer over the library."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import click

from . import __version__


def _size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected HxW, e.g. 96x320; got {text!r}") from None
    return h, w


class _Group(click.Group):
    """Turns the library's bad-input errors (a missing or corrupt file, a wrong size, an
    unsafe checkpoint, an existing output) into one-line CLI errors, for every command."""

    def invoke(self, ctx: click.Context):  # type: ignore[no-untyped-def]
        try:
            return super().invoke(ctx)
        except (ValueError, FileExistsError, pickle.UnpicklingError) as exc:
            raise click.ClickException(str(exc)) from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
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
    help="Folder for the data, runs, pictures and report.",
)
@click.option("--minutes", default=6.0, show_default=True, help="Training budget of the two models together.")
@click.option("--size", default="96x320", show_default=True, help="Scene size HxW (multiples of 32).")
@click.option("--frames", default=200, show_default=True, help="Training scenes.")
@click.option("--eval-frames", default=16, show_default=True, help="Held-out scenes (half shadowed).")
@click.option("--width", default=0.125, show_default=True, help="Model width multiplier (1.0 = paper).")
@click.option("--steps", default=None, help="Fixed steps per model as BACKBONE,FULL instead of the time budget.")
@click.option("--seed", default=0, show_default=True)
@click.option("--device", default="auto", show_default=True, help="auto, cpu or cuda[:N].")
@click.option("--overwrite", is_flag=True, help="Replace the contents of --out.")
def demo(out_dir: Path, minutes: float, size: str, frames: int, eval_frames: int, width: float, steps: str | None,
         seed: int, device: str, overwrite: bool) -> None:  # fmt: skip
    """Synthetic data -> train SemAttNet and the two-branch ablation -> evaluate -> HTML report."""
    from .demo import DemoSettings, run_demo

    fixed = None
    if steps is not None:
        try:
            bb, full = (int(v) for v in steps.split(","))
        except ValueError:
            msg = f"expected BACKBONE,FULL step counts, got {steps!r}"
            raise click.BadParameter(msg, param_hint="--steps") from None
        fixed = (bb, full)
    settings = DemoSettings(size=_size(size), train_frames=frames, eval_frames=eval_frames, width=width,
                            minutes=minutes, steps=fixed, seed=seed, device=device)  # fmt: skip
    run_demo(out_dir, settings, overwrite=overwrite, log=click.echo)


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

    ckpt = load_checkpoint(checkpoint)
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
    ckpt = load_checkpoint(src)
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

    manifest = write_synthetic_kitti(out_dir, frames, _size(size), seed, eval_frames, workers, overwrite)
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
    from .engine import train as run_training
    from .train_config import TrainConfig

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
    click.echo(f"done: epoch {result['epoch']}, step {result['step']}, best RMSE {result['best_rmse_mm']:.1f} mm")


@main.command()
@click.argument("pred_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.argument("gt_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the metrics as JSON.",
)
@click.option("--min-gt", default=0.0, show_default=True, help="Count gt > this (0.1 = the authors' variant).")
@click.option("--no-fill", is_flag=True, help="Do not fill prediction holes (the devkit fills them).")
def metrics(pred_dir: Path, gt_dir: Path, json_path: Path | None, min_gt: float, no_fill: bool) -> None:
    """Score 16-bit PNG depth predictions against ground truth (KITTI devkit metrics)."""
    from .evaluation import score_folders

    m = score_folders(pred_dir, gt_dir, fill_holes=not no_fill, min_gt=min_gt)
    click.echo(m.table())
    if json_path is not None:
        json_path.write_text(json.dumps(m.compute(), indent=2) + "\n")


@main.command()
@click.option("--checkpoint", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--data", "data_root", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--split", type=click.Choice(["val_select", "val"]), default="val_select", show_default=True)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for metrics.json, per_image.csv, predictions/ and pictures/.",
)
@click.option("--save-predictions", is_flag=True, help="Write 16-bit PNG predictions (needs --out).")
@click.option("--pictures", default=0, show_default=True, help="Branch panels for the first N frames (needs --out).")
@click.option("--device", default="auto", show_default=True)
@click.option("--batch-size", default=1, show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@click.option("--workers", default=2, show_default=True)
@click.option("--max-frames", type=int, default=None)
@click.option("--overwrite", is_flag=True)
def evaluate(checkpoint: Path, data_root: Path, split: str, out: Path | None, save_predictions: bool, pictures: int,
             device: str, batch_size: int, amp: str, workers: int, max_frames: int | None,
             overwrite: bool) -> None:  # fmt: skip
    """Evaluate a checkpoint on a KITTI (or synthetic) split with the official metrics."""
    from .evaluation import evaluate_checkpoint

    if (save_predictions or pictures) and out is None:
        raise click.UsageError("--save-predictions and --pictures need --out")
    res = evaluate_checkpoint(checkpoint, data_root, split, out, device, batch_size, amp, workers,
                              save_predictions, pictures, max_frames, overwrite)  # fmt: skip
    click.echo(res["metrics"].table())
    if out is not None:
        click.echo(f"wrote {out / 'metrics.json'} and {out / 'per_image.csv'}")


def _frames(rgb: Path, sparse: Path, semantic: Path | None) -> list[tuple[str, Path, Path, Path | None]]:
    """Pair image files with sparse (and semantic) files by name; KITTI's val_selection_cropped
    names (``..._image_...`` / ``..._velodyne_raw_...``) pair too."""
    if rgb.is_file():
        return [(rgb.stem, rgb, sparse, semantic)]
    frames, missing = [], []
    for image in sorted(rgb.glob("*.png")):
        names = (image.name, image.name.replace("_image_", "_velodyne_raw_", 1))
        lidar = next((sparse / n for n in names if (sparse / n).is_file()), None)
        sem = None if semantic is None else semantic / image.name
        if lidar is None or (sem is not None and not sem.is_file()):
            missing.append(image.name)
            continue
        frames.append((image.stem, image, lidar, sem))
    if missing:
        raise click.ClickException(
            f"{rgb}: no matching sparse/semantic file for {len(missing)} image(s), e.g. {missing[:3]}"
        )
    if not frames:
        raise click.ClickException(f"{rgb}: no PNG images")
    return frames


@main.command()
@click.option(
    "--checkpoint",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Model weights (not needed with --method classical).",
)
@click.option("--rgb", required=True, type=click.Path(exists=True, path_type=Path), help="PNG file or folder.")
@click.option(
    "--sparse", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder."
)
@click.option("--semantic", type=click.Path(exists=True, path_type=Path), default=None, help="PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--npy", is_flag=True, help="Also write float32 .npy depth.")
@click.option("--panel", is_flag=True, help="Also write the per-branch panel.")
@click.option("--device", default="auto", show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@click.option("--overwrite", is_flag=True, help="Replace existing outputs.")
@click.option(
    "--method",
    type=click.Choice(["semattnet", "classical"]),
    default="semattnet",
    show_default=True,
    help="classical: the non-learned IP-Basic-style baseline (no checkpoint).",
)
def predict(checkpoint: Path | None, rgb: Path, sparse: Path, semantic: Path | None, out: Path, npy: bool, panel: bool,
            device: str, amp: str, overwrite: bool, method: str) -> None:  # fmt: skip
    """Complete depth for one frame or folders of frames (any size)."""
    import numpy as np
    import torch

    from .classical import complete_classical
    from .data.io import read_depth, read_image, write_depth, write_image
    from .inference import Completion, DepthCompleter, clamp_for_png
    from .visualize import branch_panel, colorize_depth

    if method == "semattnet" and checkpoint is None:
        raise click.UsageError("--checkpoint is required (or --method classical)")
    frames = _frames(rgb, sparse, semantic)
    targets = [out / f"{name}{suffix}" for name, *_ in frames for suffix in (".png", "_color.png")]
    existing = [p for p in targets if p.exists()]
    if existing and not overwrite:
        raise click.ClickException(f"{len(existing)} output(s) exist, e.g. {existing[0]}; pass --overwrite")
    completer = DepthCompleter.from_checkpoint(checkpoint, device=device, amp=amp) if method == "semattnet" else None
    for name, rgb_p, sparse_p, sem_p in frames:
        image, lidar = read_image(rgb_p), read_depth(sparse_p)
        sem = read_image(sem_p) if sem_p is not None else None
        if completer is None:
            dense = complete_classical(torch.from_numpy(lidar)[None, None])[0, 0].numpy()
            result = Completion(depth=dense, outputs={"refined_depth": dense})
        else:
            result = completer(image, lidar, sem)
        depth = clamp_for_png(result.depth, name)
        write_depth(out / f"{name}.png", depth, overwrite=True)
        write_image(out / f"{name}_color.png", colorize_depth(depth), overwrite=True)
        if npy:
            np.save(out / f"{name}.npy", result.depth.astype(np.float32))
        if panel:
            branch_panel(out / f"{name}_panel.png", image, sem, lidar, result.outputs)
        click.echo(f"{name}: {result.depth.shape[1]}x{result.depth.shape[0]} -> {out / (name + '.png')}")


@main.command()
@click.option("--checkpoint", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--data", "data_root", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Folder; OUT.zip is written too."
)
@click.option("--expected-frames", default=1000, show_default=True, help="0 accepts any count (synthetic data).")
@click.option("--device", default="auto", show_default=True)
@click.option("--amp", type=click.Choice(["none", "bf16", "fp16"]), default="none", show_default=True)
@click.option("--overwrite", is_flag=True)
def submit(checkpoint: Path, data_root: Path, out: Path, expected_frames: int, device: str, amp: str,
           overwrite: bool) -> None:  # fmt: skip
    """Predict the KITTI test split and write the zip to upload (checked before zipping)."""
    from .evaluation import write_submission

    zip_path = write_submission(checkpoint, data_root, out, device, amp, expected_frames or None, overwrite)
    click.echo(f"wrote {out} and {zip_path}")


@main.command()
@click.option("--pred", required=True, type=click.Path(exists=True, path_type=Path), help="16-bit PNG file or folder.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option("--gt", type=click.Path(exists=True, path_type=Path), default=None, help="Ground truth: adds error maps.")
@click.option("--vmax", default=80.0, show_default=True, help="Depth of the colour scale's top, metres.")
def visualize(pred: Path, out: Path, gt: Path | None, vmax: float) -> None:
    """Colourise saved depth predictions (and error maps against ground truth)."""
    from .data.io import read_depth, write_image
    from .visualize import colorize_depth, error_map

    files = [pred] if pred.is_file() else sorted(pred.glob("*.png"))
    for f in files:
        d = read_depth(f)
        write_image(out / f"{f.stem}_color.png", colorize_depth(d, vmax), overwrite=True)
        if gt is not None:
            g = read_depth(gt if gt.is_file() else gt / f.name)
            write_image(out / f"{f.stem}_error.png", error_map(d, g), overwrite=True)
    click.echo(f"wrote {len(files)} picture(s) to {out}")


@main.command(context_settings={"show_default": True})
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default="semattnet-ablation",
              help="Folder for data, runs and results; rerun to continue an interrupted ablation.")  # fmt: skip
@click.option("--configs", default="all", help="Comma-separated table2_a ... table2_g, g_unknown_semantics.")
@click.option("--seeds", default="0,1,2", help="Comma-separated training seeds.")
@click.option("--backbone-steps", default=90, help="Backbone-stage steps (refining configurations).")
@click.option("--full-steps", default=40, help="Full-model steps (non-refining configurations: more backbone steps).")
@click.option("--size", default="96x320", help="Scene size HxW.")
@click.option("--frames", default=200, help="Training scenes.")
@click.option("--eval-frames", default=16, help="Held-out scenes (half shadowed).")
@click.option("--width", default=0.125, help="Model width multiplier.")
@click.option("--device", default="auto")
def ablate(out_dir: Path, configs: str, seeds: str, backbone_steps: int, full_steps: int, size: str, frames: int,
           eval_frames: int, width: float, device: str) -> None:  # fmt: skip
    """Table 2 configurations (a)-(g) on synthetic scenes: RMSE per configuration, shadowed and not, over seeds."""
    from .ablate import CONFIGS, AblationSettings, run_ablation

    try:
        seed_list = tuple(int(v) for v in seeds.split(","))
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {seeds!r}", param_hint="--seeds") from None
    chosen = CONFIGS if configs == "all" else tuple(c.strip() for c in configs.split(",") if c.strip())
    settings = AblationSettings(size=_size(size), train_frames=frames, eval_frames=eval_frames, width=width,
                                backbone_steps=backbone_steps, full_steps=full_steps, seeds=seed_list,
                                configs=chosen, device=device)  # fmt: skip
    run_ablation(out_dir, settings, log=click.echo)
    click.echo((out_dir / "ablation.md").read_text())


@main.command(context_settings={"show_default": True})
@click.option("--size", default="352x1216", help="Frame size HxW for inference.")
@click.option("--train-size", default="320x1216", help="Crop size HxW for the training step.")
@click.option("--device", default="auto", help="auto, cpu or cuda[:N].")
@click.option("--repeats", default=3, help="Timed runs per measurement (median reported).")
@click.option("--width", default=1.0, help="Model width multiplier (1.0 = paper).")
@click.option("--parts", default="propagation,backbone,full,fast,train", help="What to measure.")
@click.option("--checkpoint", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Weights to use instead of random ones.")  # fmt: skip
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the results as JSON.")  # fmt: skip
def bench(size: str, train_size: str, device: str, repeats: int, width: float, parts: str, checkpoint: Path | None,
          json_path: Path | None) -> None:  # fmt: skip
    """Latency, throughput and peak memory against the naive reference, in one process."""
    from ._device import resolve_device
    from .benchmark import run_benchmark
    from .checkpoint import load_model

    model = load_model(checkpoint) if checkpoint is not None else None
    chosen = tuple(p.strip() for p in parts.split(",") if p.strip())
    unknown = set(chosen) - {"propagation", "backbone", "full", "fast", "train"}
    if unknown:
        raise click.BadParameter(f"unknown part(s) {sorted(unknown)}", param_hint="--parts")
    result = run_benchmark(_size(size), resolve_device(device), repeats, width, chosen, _size(train_size), model,
                           log=click.echo)  # fmt: skip
    if json_path is not None:
        json_path.write_text(json.dumps(result.to_dict(), indent=2) + "\n")


def _triple(text: str, option: str) -> tuple[float, float, float]:
    try:
        a, b, c = (float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(f"expected three numbers R,G,B; got {text!r}", param_hint=option) from None
    return a, b, c


@main.command()
@click.option("--model", "spec", required=True,
              help="model.onnx, TorchScript file, torchvision:ARCH:WEIGHTS, or 'unknown' (no segmenter).")  # fmt: skip
@click.option("--images", required=True, type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Image tree, e.g. kitti_raw (searched recursively).")  # fmt: skip
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Semantic root; mirrors the image tree.")  # fmt: skip
@click.option("--batch-size", default=4, show_default=True)
@click.option("--device", default="auto", show_default=True)
@click.option("--mean", default="0.485,0.456,0.406", show_default=True, help="Input normalisation (RGB in [0, 1]).")
@click.option("--std", default="0.229,0.224,0.225", show_default=True)
@click.option("--input-size", default=None, help="Run the network at HxW (maps are resized back).")
@click.option("--overwrite", is_flag=True, help="Redo maps that already exist.")
def segment(spec: str, images: Path, out: Path, batch_size: int, device: str, mean: str, std: str,
            input_size: str | None, overwrite: bool) -> None:  # fmt: skip
    """Write Cityscapes-coloured semantic maps for every image; resumes where it stopped."""
    from .segment import load_segmenter, segment_folder

    segmenter = load_segmenter(spec, device, _triple(mean, "--mean"), _triple(std, "--std"),
                               _size(input_size) if input_size else None)  # fmt: skip
    done = segment_folder(segmenter, images, out, batch_size=batch_size, overwrite=overwrite)
    click.echo(f"wrote {done.written} maps to {out} ({done.skipped} already there, {done.total} images)")


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


if __name__ == "__main__":
    main()
