"""The domain-shift benchmark: a model trained on one rig, measured on another, before and after self-supervised
adaptation, beside the model trained with ground truth on the new rig and the classical completion.

One command (a GPU machine; from the repository root, the package installed or ``PYTHONPATH=src``):

    python benchmarks/shift.py --out shift-run --device cuda

Domains (:mod:`semattnet.synthetic.domain`): ``source`` is the generator's original rig (64 beams, KITTI's
camera and mounting), ``target`` another car's (a lower, tilted 32-beam LiDAR, a lower camera pitched down with
a wider lens and another image size, other light and paint); the same kind of streets (the realistic style).

Steps, each resumable (a tree or a checkpoint an earlier run left complete is read back, not made again):

1. data: the source training scenes (the demo reference's: 400 scenes, data seed 1000, 96x320), target
   training scenes (400, data seed 2000, 128x352: only for the supervised upper bound), one target recording
   for adaptation (a KITTI raw drive through 20 streets of 20 frames, stereo pair, LiDAR sweeps, OXTS; its
   ground truth is never read) and the held-out target scenes (the demo's data seed 0, 16 scenes, 128x352)
   with ground truth; the demo's 16 held-out source scenes for reference.
2. training: the source model and the supervised-on-target model by the reference recipe
   (:data:`semattnet.apps.demo.reference.REFERENCE_RECIPE`, :func:`semattnet.apps.experiment.train_variant`),
   training seeds 0 and 1; weights in ``checkpoints/``. The source models are the shipped demo references
   (``semattnet-demo-ref-seed0/1``: this recipe on these scenes, as their records say) where the recipe is theirs.
3. adaptation (:func:`adapt_rows`): ``semattnet adapt`` of each source model on the target recording at lr 1e-3:
   the recipe (all losses, 800 steps) first, then the ablation (all losses, and each alone, 400 steps); skipped
   (one line) where this checkout has no ``adapt`` command.
4. scores on the held-out target scenes (RMSE, MAE, iRMSE, iMAE, means over scenes, then over seeds):
   unadapted, adapted, supervised on the target, classical; ``results.json`` (atomic; refused if present
   without ``--overwrite``), and the table and the plot into ``docs/guides/domain-shift.md`` (between its
   markers) and ``docs/domain-shift.png``.

``--tiny`` runs every step at a toy size (seconds; what the tests run) and leaves the docs alone unless
``--docs`` names a page.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import shutil
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.device import resolve_device
from semattnet._utils.outputs import incomplete_tree
from semattnet.apps.demo.reference import REFERENCE_RECIPE, ReferenceRecipe, machine_line, reference_for
from semattnet.apps.experiment import HeldOut, complete_held_out, fallback_semantic, load_held_out, score_held_out
from semattnet.apps.experiment import train_variant as _train_variant
from semattnet.baselines.classical import complete_classical
from semattnet.models.registry import build_model
from semattnet.synthetic.domain import SOURCE, TARGET, Domain
from semattnet.synthetic.drive import drive_name, write_synthetic_drives
from semattnet.synthetic.tree import SYNTH_DATE, write_synthetic_kitti
from semattnet.weights.checkpoint import load_checkpoint, load_weights, save_safetensors

#: The command of the full run (results.json records it).
COMMAND = "python benchmarks/shift.py --out shift-run --device cuda"
REPO = Path(__file__).resolve().parents[1]
DOC_PAGE = REPO / "docs" / "guides" / "domain-shift.md"
PLOT = REPO / "docs" / "domain-shift.png"
MARKERS = ("<!-- shift-results:start -->", "<!-- shift-results:end -->")
GAP_MARKERS = ("<!-- shift-gap:start -->", "<!-- shift-gap:end -->")
#: The groups of :class:`~semattnet.synthetic.domain.Domain` fields the rigs differ in (``--references``).
FACTORS: dict[str, tuple[str, ...]] = {
    "image size": (),
    "LiDAR": ("beams", "elevation", "lidar_offset", "lidar_pitch"),
    "camera mounting": ("camera_height", "camera_pitch"),
    "lens": ("focal_scale", "principal_row"),
    "light and paint": ("sun_x", "sun_z", "exposure", "albedo_gain", "noise"),
}
#: Scores, as :class:`semattnet.evaluation.metrics.KittiMetrics` names them (mm and 1/km).
METRICS = ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km")
#: Adapted rows: key -> the ``--loss`` of ``semattnet adapt``. ``all`` is the recipe (``adapt_steps``); the others
#: are its ablation, each loss alone and all together, at ``ablation_steps``.
LOSSES = {
    "all": "sparse,photometric,smoothness",
    "all_short": "sparse,photometric,smoothness",
    "sparse": "sparse",
    "photometric": "photometric",
    "smoothness": "smoothness",
}
#: Rows of the table, in order, with their labels.
ROWS = {
    "classical": "classical completion",
    "unadapted": "source model, unadapted",
    **{
        f"adapted_{k}": f"adapted: {LOSSES[k].replace(',', ' + ')}, {{short}} steps"
        for k in ("sparse", "photometric", "smoothness", "all_short")
    },
    "adapted_all": "adapted: all three losses, {long} steps (the recipe)",
    "supervised": "supervised on the target (upper bound)",
    "unadapted_on_source": "source model on held-out *source* scenes",
}


def row_label(key: str, settings: dict[str, Any]) -> str:
    """The label of the row ``key`` of a run with ``settings`` (``results.json``'s)."""
    steps = settings["adapt_steps"]
    return ROWS[key].format(long=steps, short=settings.get("ablation_steps", steps))


@dataclass(frozen=True)
class ShiftSettings:
    """What the benchmark generates, trains and adapts (the defaults are the full run)."""

    recipe: ReferenceRecipe = REFERENCE_RECIPE  # both models; the supervised one at target_size
    style: str = "realistic"
    target_size: tuple[int, int] = (128, 352)
    target_data_seed: int = 2000
    held_out_seed: int = 0  # the demo's
    held_out_frames: int = 16
    streets: int = 20  # of the adaptation recording (one drive folder)
    street_frames: int = 20
    drive_seed: int = 3000
    adapt_steps: int = 800  # the recipe's (all losses)
    ablation_steps: int = 400  # each loss alone, and all of them, for the ablation
    adapt_lr: float = 1e-3  # adapt's default 1e-4 moves a model trained elsewhere too slowly in 400 steps

    def steps_for(self, key: str) -> int:
        """Adaptation steps of the row ``adapted_<key>``."""
        return self.adapt_steps if key == "all" else self.ablation_steps

    seeds: tuple[int, ...] = (0, 1)
    fallback_map: bool = False  # score (and adapt) with the no-segmenter map instead of the scenes' maps


def tiny(seeds: tuple[int, ...] = (0,)) -> ShiftSettings:
    """Every step at a toy size: a check that the whole benchmark runs (seconds on a CPU)."""
    recipe = dataclasses.replace(
        REFERENCE_RECIPE,
        train_frames=4,
        val_frames=2,
        size=(64, 96),
        batch_size=2,
        backbone_steps=1,
        refine_init_steps=1,
        full_steps=1,
    )
    return ShiftSettings(
        recipe=recipe,
        target_size=(64, 128),
        held_out_frames=2,
        streets=2,
        street_frames=3,
        adapt_steps=2,
        ablation_steps=1,
        seeds=seeds,
    )


class Clock:
    """Seconds per named step, for the record (``results.json`` ``seconds``): ``with clock("data"): ...``."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = round(self.seconds.get(name, 0.0) + time.perf_counter() - start, 2)


def _tree(
    root: Path, frames: int, eval_frames: int, size: tuple[int, int], seed: int, style: str, domain: str | Domain
) -> HeldOut:
    """A synthetic tree (:func:`~semattnet.synthetic.tree.write_synthetic_kitti`): the one an earlier run
    completed, else written anew; its held-out scenes."""
    done = (root / "scenes.json").is_file() and incomplete_tree(root) is None
    if not done:
        write_synthetic_kitti(
            root,
            frames=frames,
            size=size,
            seed=seed,
            eval_frames=eval_frames,
            style=style,
            domain=domain,
            overwrite=root.exists(),
        )
    return load_held_out(root)


def make_data(out: Path, s: ShiftSettings, clock: Clock) -> dict[str, Any]:
    """Step 1: every tree and the adaptation recording (see the module doc); the held-out sets and paths."""
    r = s.recipe
    data: dict[str, Any] = {"source_train": out / "data" / "source", "target_train": out / "data" / "target"}
    rec = out / "data" / "recording"
    with clock("data"):
        _tree(data["source_train"], r.train_frames, r.val_frames, r.size, r.data_seed, s.style, "source")
        _tree(data["target_train"], r.train_frames, r.val_frames, s.target_size, s.target_data_seed, s.style, "target")
        data["held_target"] = _tree(
            out / "data" / "held_out_target", 2, s.held_out_frames, s.target_size, s.held_out_seed, s.style, "target"
        )
        data["held_source"] = _tree(
            out / "data" / "held_out_source", 2, s.held_out_frames, r.size, s.held_out_seed, s.style, "source"
        )
        if not (rec / "drives.json").is_file() or incomplete_tree(rec) is not None:
            write_synthetic_drives(
                rec, 1, s.street_frames, s.target_size, s.drive_seed, s.style, "target", rec.exists(), streets=s.streets
            )
    data["drive"] = rec / "kitti_raw" / SYNTH_DATE / drive_name(0)
    data["semantic"] = rec / "semantic" / SYNTH_DATE / drive_name(0) / "image_02" / "data"
    return data


def load_model(path: Path) -> torch.nn.Module:
    """The model of a checkpoint (its config from the file), in eval mode."""
    ckpt = load_checkpoint(path)
    model = build_model(config=ckpt.config)
    load_weights(model, ckpt)
    return model.eval()


def train_model(
    out: Path,
    key: str,
    data: Path,
    size: tuple[int, int],
    s: ShiftSettings,
    seed: int,
    device: torch.device,
    log: Callable[[str], None],
) -> Path:
    """Step 2, one model and seed by the recipe: ``checkpoints/<key>_seed<S>.safetensors`` (read back when an
    earlier run left it)."""
    saved = out / "checkpoints" / f"{key}_seed{seed}.safetensors"
    if saved.is_file():
        log(f"[shift] {key}, seed {seed}: trained earlier ({saved})")
        return saved
    r = s.recipe
    if key == "source" and size == r.size and (shipped := reference_for(dataclasses.replace(r, seed=seed), seed)):
        log(f"[shift] {key}, seed {seed}: the shipped reference {shipped.name}, trained by this recipe on these scenes")
        save_safetensors(load_checkpoint(shipped), saved)
        return saved
    log(f"[shift] {key}, seed {seed}: training on {data} at {size[0]}x{size[1]} ...")
    last = _train_variant(
        out / "runs" / f"{key}_seed{seed}",
        data,
        r.backbone_steps,
        r.full_steps,
        size=size,
        width=r.width,
        batch_size=r.batch_size,
        lr=r.lr,
        seed=seed,
        device=device,
        log=log,
        refine_init_steps=r.refine_init_steps,
        head_lr_factor=r.head_lr_factor,
        loss=r.loss,
        semantic_dropout=r.semantic_dropout,
        branches=3,
    )
    save_safetensors(load_checkpoint(last), saved)
    return saved


def scores(preds: dict[str, np.ndarray], held: HeldOut) -> dict[str, float]:
    """The four metrics (means over the held-out scenes)."""
    return {k: float(score_held_out(preds, held)["all"][k]) for k in METRICS}


def score_model(path: Path, held: HeldOut, s: ShiftSettings, device: torch.device) -> dict[str, float]:
    """A checkpoint's final depth on the held-out scenes, scored (the fallback map with ``s.fallback_map``)."""
    semantic = fallback_semantic if s.fallback_map else None
    outputs = complete_held_out(load_model(path), held, device, semantic)
    return scores({n: o["refined_depth"] for n, o in outputs.items()}, held)


def _row(per_seed: dict[str, dict[str, float]], **extra: Any) -> dict[str, Any]:
    mean = {k: statistics.fmean(v[k] for v in per_seed.values()) for k in METRICS}
    return {**extra, "per_seed": per_seed, "scores": mean}


def adapt_available() -> bool:
    """Whether this checkout's CLI has ``semattnet adapt``."""
    from semattnet.cli import main

    return "adapt" in getattr(main, "commands", {})


def adapt_one(
    weights: Path, drive: Path, run: Path, steps: int, loss: str, seed: int, semantic: Path | None, lr: float = 1e-3
) -> Path:
    """``semattnet adapt`` (through the CLI's ``main``) of ``weights`` on the recording ``drive``; returns
    ``run/adapted.safetensors``."""
    from semattnet.cli import main

    args = [
        "adapt",
        "--weights",
        str(weights),
        "--kitti-raw",
        str(drive),
        "--out",
        str(run),
        "--steps",
        str(steps),
        "--loss",
        loss,
        "--seed",
        str(seed),
        "--lr",
        str(lr),
    ]
    if semantic is not None:
        args += ["--semantic", str(semantic)]
    main.main(args=args, prog_name="semattnet", standalone_mode=False)
    return run / "adapted.safetensors"


def adapt_rows(
    out: Path,
    source: dict[int, Path],
    data: dict[str, Any],
    s: ShiftSettings,
    device: torch.device,
    clock: Clock,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Step 3: each source model adapted on the target recording with each loss of :data:`LOSSES` (no ground
    truth read), scored; ``{}`` and one line where ``semattnet adapt`` is not available."""
    if not adapt_available():
        log("[shift] adapted rows skipped: this checkout has no `semattnet adapt` command")
        return {}
    semantic = None if s.fallback_map else data["semantic"]
    rows: dict[str, Any] = {}
    for key, loss in LOSSES.items():
        per_seed = {}
        for seed, weights in source.items():
            saved = out / "checkpoints" / f"adapted_{key}_seed{seed}.safetensors"
            if not saved.is_file():
                log(f"[shift] adapting seed {seed} with {loss} ...")
                with clock(f"adapt_{key}"):
                    adapted = adapt_one(
                        weights,
                        data["drive"],
                        out / "adapt" / f"{key}_seed{seed}",
                        s.steps_for(key),
                        loss,
                        seed,
                        semantic,
                        s.adapt_lr,
                    )
                with atomic_path(saved, suffix=".safetensors") as tmp:
                    shutil.copyfile(adapted, tmp)
            per_seed[str(seed)] = score_model(saved, data["held_target"], s, device)
        rows[f"adapted_{key}"] = _row(per_seed, loss=loss)
    return rows


def estimate(s: ShiftSettings, device: torch.device) -> dict[str, float]:
    """Minutes each step of a run with settings ``s`` takes on ``device``, estimated from timed pieces: the
    generator per frame (each size), one training step per size (:func:`~semattnet.apps.experiment.step_seconds`,
    the fastest of 2) times the recipe's steps; adaptation as 2.5 training steps per step (two views rendered
    through the model and back for the photometric loss: an assumption until ``semattnet adapt`` is timed)."""
    from semattnet.apps.experiment import step_seconds
    from semattnet.synthetic.drive import make_drive
    from semattnet.synthetic.scenes import make_frame

    r = s.recipe

    def per_frame(size: tuple[int, int], domain: str) -> float:
        start = time.perf_counter()
        make_frame(*size, seed=1, style=s.style, domain=domain)
        return time.perf_counter() - start

    start = time.perf_counter()
    list(make_drive(2, s.target_size, 1, s.style, "target"))
    drive_frame = (time.perf_counter() - start) / 2
    frames = {
        "source": r.train_frames + 4 * r.val_frames + 2 + 3 * s.held_out_frames,
        "target": r.train_frames + 4 * r.val_frames + 2 + 3 * s.held_out_frames,
    }
    data = frames["source"] * per_frame(r.size, "source") + frames["target"] * per_frame(s.target_size, "target")
    data += s.streets * s.street_frames * drive_frame
    steps = r.backbone_steps + r.refine_init_steps + r.full_steps
    step = {
        k: step_seconds(size, r.batch_size, device, repeats=2, width=r.width)
        for k, size in (("source", r.size), ("target", s.target_size))
    }
    n = len(s.seeds)
    return {
        "data_min": round(data / 60, 1),
        "seconds_per_training_step_source": round(step["source"], 3),
        "seconds_per_training_step_target": round(step["target"], 3),
        "train_min": round(n * steps * (step["source"] + step["target"]) / 60, 1),
        "adapt_min": round(n * sum(map(s.steps_for, LOSSES)) * 2.5 * step["target"] / 60, 1),
    }


def summary(rows: dict[str, Any]) -> dict[str, Any]:
    """The issue's acceptance: the share of the RMSE gap (unadapted -> supervised) adaptation with all losses
    closes (>= 0.5) and whether it beats the classical completion on all four metrics (seed means)."""
    if "adapted_all" not in rows:
        return {}
    rmse = {k: rows[k]["scores"]["rmse_mm"] for k in ("unadapted", "adapted_all", "supervised")}
    gap = rmse["unadapted"] - rmse["supervised"]
    closed = (rmse["unadapted"] - rmse["adapted_all"]) / gap if gap > 0 else float("nan")
    beats = all(rows["adapted_all"]["scores"][k] < rows["classical"]["scores"][k] for k in METRICS)
    return {"gap_closed": closed, "beats_classical": beats, "accepted": bool(closed >= 0.5 and beats)}


def run(
    out: Path,
    s: ShiftSettings,
    device: torch.device,
    overwrite: bool = False,
    command: str = COMMAND,
    extra: dict[str, Any] | None = None,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Every step (see the module doc); returns what ``out/results.json`` holds (``command``: how it was run;
    ``extra``: more to record)."""
    target = out / "results.json"
    if target.exists() and not overwrite:
        raise InputError(f"{target} exists; pass --overwrite to replace it")
    clock, start = Clock(), time.perf_counter()
    data = make_data(out, s, clock)
    held = data["held_target"]
    source, supervised = {}, {}
    for seed in s.seeds:
        with clock("train_source"):
            source[seed] = train_model(out, "source", data["source_train"], s.recipe.size, s, seed, device, log)
        with clock("train_supervised"):
            supervised[seed] = train_model(out, "supervised", data["target_train"], s.target_size, s, seed, device, log)
    with clock("score"):
        classical = {
            n: complete_classical(x["sparse"][None])[0, 0].numpy()
            for n, x in zip(held.names, held.samples, strict=True)
        }
        rows: dict[str, Any] = {"classical": {"scores": scores(classical, held)}}
        rows["unadapted"] = _row({str(k): score_model(p, held, s, device) for k, p in source.items()})
        rows["unadapted_on_source"] = _row(
            {str(k): score_model(p, data["held_source"], s, device) for k, p in source.items()}
        )
    rows |= adapt_rows(out, source, data, s, device, clock, log)
    with clock("score"):
        rows["supervised"] = _row({str(k): score_model(p, held, s, device) for k, p in supervised.items()})
    results = {
        "command": command,
        "settings": dataclasses.asdict(s),
        "domains": {"source": dataclasses.asdict(SOURCE), "target": dataclasses.asdict(TARGET)},
        "device": str(device),
        "machine": machine_line(),
        "torch": torch.__version__,
        "seconds": {**clock.seconds, "total": round(time.perf_counter() - start, 1)},
        "rows": rows,
        "summary": summary(rows),
        **(extra or {}),
    }
    with atomic_path(target) as tmp:
        tmp.write_text(json.dumps(results, indent=1, default=str) + "\n")
    log(f"[shift] wrote {target}")
    return results


def table(results: dict[str, Any]) -> str:
    """The markdown table of the held-out target scores (seed means; RMSE per seed), and the acceptance line."""
    rows, seeds = results["rows"], results["settings"]["seeds"]
    head = ["| method | RMSE mm | MAE mm | iRMSE 1/km | iMAE 1/km | RMSE per seed |", "|---|---:|---:|---:|---:|---|"]
    lines = []
    for key in ROWS:
        if key not in rows:
            continue
        label = row_label(key, results["settings"])
        m, per = rows[key]["scores"], rows[key].get("per_seed", {})
        per_seed = ", ".join(f"{per[str(k)]['rmse_mm']:.0f}" for k in seeds if str(k) in per)
        lines.append(
            f"| {label} | {m['rmse_mm']:.0f} | {m['mae_mm']:.0f} | {m['irmse_per_km']:.2f} | "
            f"{m['imae_per_km']:.2f} | {per_seed} |"
        )
    out = "\n".join(head + lines) + "\n"
    summ = results.get("summary") or {}
    if summ:
        out += (
            f"\nAdaptation by the recipe (all three losses, {results['settings']['adapt_steps']} steps) closes "
            f"**{100 * summ['gap_closed']:.0f} %** of the RMSE gap "
            f"between the unadapted model and the supervised upper bound (the aim: at least 50 %) and "
            f"{'beats' if summ['beats_classical'] else 'does not beat'} the classical completion on all four "
            "metrics.\n"
        )
    else:
        out += "\nNo adapted rows: the run's checkout had no `semattnet adapt` command.\n"
    return out


def plot(results: dict[str, Any], path: Path) -> Path:
    """RMSE and MAE per row: bars the seed means, dots the seeds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = results["rows"]
    keys = [k for k in ROWS if k in rows and k != "unadapted_on_source"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), dpi=90)
    for ax, metric, label in zip(axes, ("rmse_mm", "mae_mm"), ("RMSE [mm]", "MAE [mm]"), strict=True):
        x = np.arange(len(keys))
        ax.bar(x, [rows[k]["scores"][metric] for k in keys], color=[f"C{i}" for i in range(len(keys))], alpha=0.7)
        for i, k in enumerate(keys):
            seeds = [v[metric] for v in rows[k].get("per_seed", {}).values()]
            ax.plot([i] * len(seeds), seeds, "k.", markersize=6)
        ticks = [row_label(k, results["settings"]).split(" (")[0] for k in keys]
        ax.set_xticks(x, ticks, rotation=30, ha="right", fontsize=7)
        ax.set_ylabel(label)
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle("held-out target scenes (bars: mean of seeds, dots: seeds)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def replace_between(page: Path, markers: tuple[str, str], body: str) -> Path:
    """Put ``body`` between the page's two ``markers`` lines (atomically)."""
    text = page.read_text(encoding="utf-8")
    start, end = markers
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise InputError(f"{page}: needs one {start} line and one {end} line after it")
    new = text[: text.index(start) + len(start)] + "\n" + body + text[text.index(end) :]
    with atomic_path(page, suffix=".md") as tmp:
        tmp.write_text(new, encoding="utf-8")
    return page


def update_docs(page: Path, results: dict[str, Any], plot_path: Path) -> Path:
    """Put the table and a link to the plot between the page's :data:`MARKERS`."""
    rel = Path("..") / plot_path.name if plot_path.parent == page.parent.parent else Path(plot_path.name)
    s = results["settings"]
    body = (
        f"\nRun: `{results['command']}`, seeds {', '.join(map(str, s['seeds']))}, {results['device']} "
        f"({results['machine']}), {results['seconds']['total'] / 60:.0f} minutes.\n\n{table(results)}\n"
        f"![RMSE and MAE per method on the held-out target scenes]({rel.as_posix()})\n\n"
    )
    return replace_between(page, MARKERS, body)


def factor_domains() -> dict[str, Domain]:
    """The source rig with one group of :data:`FACTORS` taken from the target's (and the whole target)."""
    out = {}
    for factor, fields in FACTORS.items():
        changes = {f: getattr(TARGET, f) for f in fields}
        out[factor] = dataclasses.replace(SOURCE, name=f"source+{factor.replace(' ', '-')}", **changes)
    return {**out, "all: the target": TARGET}


def reference_gap(
    out: Path, s: ShiftSettings, device: torch.device, log: Callable[[str], None] = print
) -> dict[str, Any]:
    """How big the shift is, without training: the shipped reference checkpoints and the classical completion on
    the held-out scenes of the source (at the source size) and of each of :func:`factor_domains` (at the target
    size); ``out/reference_gap.json``."""
    from semattnet.apps.demo.reference import load_reference, shipped_references

    refs = {seed: load_reference(path)[0] for seed, path in shipped_references().items()}
    cases = {"source": (SOURCE, s.recipe.size), **{k: (d, s.target_size) for k, d in factor_domains().items()}}
    rows: dict[str, Any] = {}
    for name, (domain, size) in cases.items():
        root = out / "data" / f"held_out_{domain.name}"
        held = _tree(root, 2, s.held_out_frames, size, s.held_out_seed, s.style, domain)
        classical = {
            n: complete_classical(x["sparse"][None])[0, 0].numpy()
            for n, x in zip(held.names, held.samples, strict=True)
        }
        per_seed = {}
        for seed, model in refs.items():
            outputs = complete_held_out(model, held, device, fallback_semantic if s.fallback_map else None)
            per_seed[str(seed)] = scores({n: o["refined_depth"] for n, o in outputs.items()}, held)
        rows[name] = {"classical": scores(classical, held), "reference": _row(per_seed)}
        log(
            f"[shift] {name}: reference RMSE {rows[name]['reference']['scores']['rmse_mm']:.0f} mm, classical "
            f"{rows[name]['classical']['rmse_mm']:.0f} mm"
        )
    with atomic_path(out / "reference_gap.json") as tmp:
        tmp.write_text(json.dumps({"settings": dataclasses.asdict(s), "rows": rows}, indent=1, default=str) + "\n")
    return rows


def gap_table(rows: dict[str, Any]) -> str:
    """The markdown table of :func:`reference_gap`."""
    lines = [
        "| held-out scenes | reference RMSE mm | reference MAE mm | classical RMSE mm | classical MAE mm |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, row in rows.items():
        ref, cl = row["reference"]["scores"], row["classical"]
        label = name if name in ("source", "all: the target") else f"source rig, the target's {name}"
        lines.append(
            f"| {label} | {ref['rmse_mm']:.0f} | {ref['mae_mm']:.0f} | {cl['rmse_mm']:.0f} | {cl['mae_mm']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--device", default="auto", choices=("auto", "cuda", "cpu"))
    ap.add_argument("--seeds", default="", help="training seeds, e.g. 0,1 (default: 0,1; --tiny: 0)")
    ap.add_argument("--tiny", action="store_true", help="every step at a toy size (a check; docs left alone)")
    ap.add_argument("--fallback-map", action="store_true", help="score and adapt with the no-segmenter map")
    ap.add_argument(
        "--docs", type=Path, default=None, help=f"the page to update (default: {DOC_PAGE.name}; --tiny: none)"
    )
    ap.add_argument("--plot", type=Path, default=None, help=f"the plot to write (default: docs/{PLOT.name})")
    ap.add_argument("--overwrite", action="store_true", help="replace results.json (checkpoints are reused)")
    ap.add_argument(
        "--references",
        action="store_true",
        help="only score the shipped references on the source "
        "and on each factor of the shift (no training): the page's first table",
    )
    ap.add_argument(
        "--estimate",
        action="store_true",
        help="first time a frame and a training step per size on "
        "--device and record the full run's minutes estimated from them",
    )
    args = ap.parse_args(argv)
    try:
        seeds = tuple(int(v) for v in args.seeds.split(",")) if args.seeds else None
    except ValueError:
        raise InputError(f"--seeds must be integers separated by commas, e.g. 0,1; got {args.seeds!r}") from None
    s = tiny() if args.tiny else ShiftSettings()
    s = dataclasses.replace(s, seeds=seeds or s.seeds, fallback_map=args.fallback_map)
    device = resolve_device(args.device)
    if args.references:
        rows = reference_gap(args.out, s, device)
        if args.docs is not None or not args.tiny:
            replace_between(args.docs or DOC_PAGE, GAP_MARKERS, "\n" + gap_table(rows) + "\n")
        print(gap_table(rows))
        return rows
    command = " ".join(["python benchmarks/shift.py", *(argv if argv is not None else sys.argv[1:])])
    extra = {"estimate_full_run": estimate(ShiftSettings(), device)} if args.estimate else {}
    if extra:
        print(f"[shift] the full run on this machine ({device}), estimated: {extra['estimate_full_run']}")
    results = run(args.out, s, device, args.overwrite, command, extra)
    page = args.docs if args.docs is not None else (None if args.tiny else DOC_PAGE)
    if page is not None:
        update_docs(page, results, plot(results, args.plot or (PLOT if page == DOC_PAGE else page.with_suffix(".png"))))
    print(table(results))
    return results


if __name__ == "__main__":
    main()
