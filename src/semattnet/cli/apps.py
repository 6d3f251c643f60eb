"""Experiments: ``demo``, ``ablate``, ``bench``."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import click

from semattnet.cli._group import main
from semattnet.cli._model import check_calibration, device_option, precision_options
from semattnet.cli._options import (
    COUNT,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    SEEDS,
    SIZE,
    WIDTH,
    check_calibration_frames,
    model_from_options,
    parse_size,
    weights_input,
    weights_option,
)
from semattnet.synthetic.scenes import SCENE_STYLES


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default="semattnet-demo",
    show_default=True,
    help="Folder for the data, runs, pictures and report.",
)
@click.option(
    "--minutes",
    type=POSITIVE_FLOAT,
    default=None,
    help="Plan the steps from this training budget (both models, all seeds) instead of --steps.",
)
@click.option("--size", type=SIZE, default="96x320", show_default=True, help="Scene size HxW (multiples of 32).")
@click.option("--frames", type=POSITIVE_INT, default=200, show_default=True, help="Training scenes.")
@click.option(
    "--eval-frames", type=POSITIVE_INT, default=16, show_default=True, help="Held-out scenes (half shadowed)."
)
@click.option("--width", type=WIDTH, default=0.125, show_default=True, help="Model width multiplier (1.0 = paper).")
@click.option(
    "--steps", default=None, help="Steps per model and seed as BACKBONE,FULL  [default: 136,80: ~4 min on 2 cores]"
)
@click.option(
    "--equal-time",
    is_flag=True,
    help="Give each model half the time instead of the same steps (the default, as the paper).",
)
@click.option("--seed", type=COUNT, default=0, show_default=True, help="Seed of the scenes.")
@click.option(
    "--seeds",
    type=SEEDS,
    default="0,1",
    show_default=True,
    help="Training seeds: each model is trained once per seed within the budget; the table shows the "
    "mean and every seed.",
)
@click.option(
    "--style",
    type=click.Choice(SCENE_STYLES),
    default="realistic",
    show_default=True,
    help="Scene style: realistic has LiDAR failures and colour edges without depth edges.",
)
@device_option()
@click.option("--no-reference", is_flag=True, help="Do not evaluate the shipped reference checkpoints.")
@click.option(
    "--train-reference",
    is_flag=True,
    help="Instead of the demo: retrain the shipped reference checkpoints into --out, one per --seeds "
    "(default 0,1; their fixed recipe, ~12 minutes each on 2 cores), writing "
    "--out/demo_reference_seedS.safetensors.gz.",
)
@click.option(
    "--semantic-dropout",
    type=click.FloatRange(0.0, 1.0),
    default=0.0,
    show_default=True,
    help="With --train-reference: the share of training frames given the fallback semantic map (a "
    "model that also works without a segmenter).",
)
@click.option("--overwrite", is_flag=True, help="Replace the contents of --out.")
def demo(
    out_dir: Path,
    minutes: float | None,
    size: str,
    frames: int,
    eval_frames: int,
    width: float,
    steps: str | None,
    equal_time: bool,
    seed: int,
    seeds: tuple[int, ...],
    style: str,
    device: str,
    no_reference: bool,
    train_reference: bool,
    semantic_dropout: float,
    overwrite: bool,
) -> None:
    """Synthetic data -> train SemAttNet and the two-branch ablation -> evaluate (with the shipped
    reference checkpoints) -> HTML report."""
    from semattnet.apps.demo import DemoSettings, run_demo, train_reference_run

    if train_reference:
        train_reference_run(
            out_dir, overwrite=overwrite, device=device, log=click.echo, seeds=seeds, semantic_dropout=semantic_dropout
        )
        return
    if semantic_dropout:
        raise click.UsageError("--semantic-dropout is an option of --train-reference")
    if steps is not None and minutes is not None:
        raise click.UsageError("give --steps or --minutes, not both")
    plan: dict[str, object] = {"steps": None, "minutes": minutes} if minutes is not None else {}
    if steps is not None:
        try:
            bb, full = (int(v) for v in steps.split(","))
        except ValueError:
            msg = f"expected BACKBONE,FULL step counts, got {steps!r}"
            raise click.BadParameter(msg, param_hint="--steps") from None
        plan = {"steps": (bb, full)}
    settings = DemoSettings(
        size=parse_size(size),
        train_frames=frames,
        eval_frames=eval_frames,
        width=width,
        seed=seed,
        seeds=seeds,
        style=style,
        device=device,
        equal_steps=not equal_time,
        reference=not no_reference,
        **plan,  # type: ignore[arg-type]
    )
    run_demo(out_dir, settings, overwrite=overwrite, log=click.echo)


@main.command(context_settings={"show_default": True})
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default="semattnet-ablation",
    help="Folder for data, runs and results; rerun to continue an interrupted ablation.",
)
@click.option(
    "--configs",
    default="all",
    help="all, claims (the five the claims need: table2_b,d,e,g, g_unknown_semantics) or a "
    "comma-separated list of table2_a ... table2_g, g_unknown_semantics.",
)
@click.option("--seeds", type=SEEDS, default="0,1,2", help="Training seeds (paired: the same for every config).")
@click.option(
    "--backbone-steps", type=POSITIVE_INT, default=400, help="Backbone-stage steps (refining configurations)."
)
@click.option(
    "--full-steps",
    type=POSITIVE_INT,
    default=150,
    help="Full-model steps (non-refining configurations: more backbone steps).",
)
@click.option("--size", type=SIZE, default="96x320", help="Scene size HxW.")
@click.option("--frames", type=POSITIVE_INT, default=200, help="Training scenes.")
@click.option("--eval-frames", type=POSITIVE_INT, default=48, help="Held-out scenes (half shadowed).")
@click.option("--width", type=WIDTH, default=0.125, help="Model width multiplier.")
@click.option("--style", type=click.Choice(SCENE_STYLES), default="realistic", help="Synthetic scene style.")
@device_option()
def ablate(
    out_dir: Path,
    configs: str,
    seeds: tuple[int, ...],
    backbone_steps: int,
    full_steps: int,
    size: str,
    frames: int,
    eval_frames: int,
    width: float,
    style: str,
    device: str,
) -> None:
    """Table 2 configurations (a)-(g) on synthetic scenes over paired seeds: RMSE and MAE per configuration,
    shadowed and not, and a paired test of each claim (semantic branch, refinement, SAMMAFB, semantic input)."""
    from semattnet.apps.ablate import CLAIM_CONFIGS, CONFIGS, AblationSettings, run_ablation

    named = {"all": CONFIGS, "claims": CLAIM_CONFIGS}
    chosen = named.get(configs) or tuple(c.strip() for c in configs.split(",") if c.strip())
    settings = AblationSettings(
        size=parse_size(size),
        train_frames=frames,
        eval_frames=eval_frames,
        width=width,
        backbone_steps=backbone_steps,
        full_steps=full_steps,
        seeds=seeds,
        configs=chosen,
        style=style,
        device=device,
    )
    run_ablation(out_dir, settings, log=click.echo)
    click.echo((out_dir / "ablation.md").read_text())


@main.command(context_settings={"show_default": True})
@click.option("--size", type=SIZE, default="352x1216", help="Frame size HxW for inference.")
@click.option("--train-size", type=SIZE, default="320x1216", help="Crop size HxW for the training step.")
@device_option()
@click.option("--repeats", type=POSITIVE_INT, default=3, help="Timed runs per measurement (median reported).")
@click.option("--width", type=WIDTH, default=1.0, help="Model width multiplier (1.0 = paper).")
@click.option(
    "--parts",
    default="propagation,backbone,full,fast,backends,train",
    help="What to measure (backends: every installed inference backend).",
)
@weights_option
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the results as JSON.",
)
@click.option("--overwrite", is_flag=True, help="Replace an existing --json file.")
@partial(precision_options, backend=False)
@click.option(
    "--outputs",
    "output_fields",
    default="",
    help="The fields the backends' engines return, e.g. "
    "refined_depth (what a robot reads: an OpenVINO graph cut to it) [default: every map].",
)
def bench(
    size: str,
    train_size: str,
    device: str,
    repeats: int,
    width: float,
    parts: str,
    weights: str | None,
    json_path: Path | None,
    overwrite: bool,
    precision: str | None,
    calibration: Path | None,
    output_fields: str,
) -> None:
    """Latency, throughput and peak memory against the naive reference, in one process. With --precision, the
    backends' rows are those of that arithmetic only (int8: OpenVINO + NNCF, calibrated on --calibration)."""
    from semattnet._utils.device import resolve_device
    from semattnet._utils.outputs import Output, check_outputs, write_text
    from semattnet.apps.benchmark import run_benchmark
    from semattnet.models.outputs import check_output_names

    check_calibration(precision)
    if calibration is not None:
        check_calibration_frames(calibration)
    if precision is not None and "backends" not in parts.split(","):
        raise click.UsageError("--precision chooses the rows of --parts backends; backends is not in --parts")
    check_outputs([weights_input(weights)], [Output("--json", json_path, "json")] if json_path else [], overwrite)
    model = model_from_options(weights) if weights is not None else None  # default: random weights
    chosen = tuple(p.strip() for p in parts.split(",") if p.strip())
    unknown = set(chosen) - {"propagation", "backbone", "full", "fast", "backends", "train"}
    if unknown:
        raise click.BadParameter(f"unknown part(s) {sorted(unknown)}", param_hint="--parts")
    fields = tuple(f.strip() for f in output_fields.split(",") if f.strip()) or None
    check_output_names(fields or (), "--outputs")
    result = run_benchmark(
        parse_size(size),
        resolve_device(device),
        repeats,
        width,
        chosen,
        parse_size(train_size),
        model,
        log=click.echo,
        precision=precision,
        calibration=calibration,
        outputs=fields,
    )
    if json_path is not None:
        write_text(json_path, json.dumps(result.to_dict(), indent=2) + "\n", overwrite=overwrite)
