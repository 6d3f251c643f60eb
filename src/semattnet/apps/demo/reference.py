"""The demo's shipped reference checkpoints: SemAttNet trained once, longer, on other synthetic scenes (one per seed).

``semattnet demo`` evaluates it beside the models it trains live (labelled "reference" in the
report and ``results.json``). ``semattnet demo --train-reference`` retrains it with
:data:`REFERENCE_RECIPE` (training scenes from their own data seed, so none of the demo's
held-out scenes is seen), once per training seed of :data:`REFERENCE_SEEDS`, and writes the
files it ships: ``semattnet/weights/assets/demo_reference_seed{S}.safetensors.gz``
(:func:`reference_path`). The demo reports the mean over these seeds and every seed.

Storage (to stay under 5 MB at width 1/8, the narrowest width the model config accepts):
:data:`REFERENCE_STORAGE`. The metadata holds the model config, the recipe, the command, the
machine and the scores on the reference's own validation scenes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from semattnet._errors import DataError
from semattnet.apps.experiment import (
    HeldOut,
    VariantRecipe,
    complete_held_out,
    fallback_semantic,
    make_synthetic,
    score_held_out,
    train_variant,
)
from semattnet.baselines.classical import complete_classical
from semattnet.models.registry import build_model
from semattnet.weights.checkpoint import load_checkpoint, load_weights
from semattnet.weights.gate import CheckpointError
from semattnet.weights.packed import PACKED_FORMAT, SHIPPED, dequantise, encode_packed, quantise, save_packed

__all__ = [
    "REFERENCE_COMMAND",
    "REFERENCE_FORMAT",
    "REFERENCE_NAME",
    "REFERENCE_PATH",
    "REFERENCE_RECIPE",
    "REFERENCE_SEEDS",
    "REFERENCE_STORAGE",
    "ReferenceError",
    "ReferenceRecipe",
    "choose_levels",
    "dequantise",
    "encode_reference",
    "load_reference",
    "machine_line",
    "package_reference",
    "quantise",
    "recipe_notes",
    "reference_command",
    "reference_for",
    "reference_path",
    "save_reference",
    "shipped_references",
    "train_reference",
]

#: The training seeds of the shipped reference checkpoints (one file each; the demo shows their mean).
REFERENCE_SEEDS: tuple[int, ...] = (0, 1)
_ASSETS = SHIPPED
#: The file name of one seed's reference checkpoint.
REFERENCE_NAME = "demo_reference_seed{seed}.safetensors.gz"


def reference_path(seed: int, folder: Path | None = None) -> Path:
    """The reference checkpoint of training seed ``seed``: in ``folder``, else the shipped one (in the package)."""
    return (folder if folder is not None else _ASSETS) / REFERENCE_NAME.format(seed=seed)


def shipped_references() -> dict[int, Path]:
    """Seed -> shipped file, for the seeds of :data:`REFERENCE_SEEDS` whose file is present."""
    return {seed: reference_path(seed) for seed in REFERENCE_SEEDS if reference_path(seed).is_file()}


#: The first seed's shipped file (inside the installed package; listed in the wheel).
REFERENCE_PATH = reference_path(REFERENCE_SEEDS[0])
REFERENCE_FORMAT = PACKED_FORMAT
#: The one command that rebuilds every file of :data:`REFERENCE_SEEDS` (copy them into the package to ship).
REFERENCE_COMMAND = "semattnet demo --train-reference --out demo-reference-run"


#: Levels per sign of the weight quantisation: the largest of these whose file is under :data:`MAX_BYTES`.
LEVELS = (127, 63, 31)
MAX_BYTES = 5_000_000
REFERENCE_STORAGE = (
    "convolution weights quantised per output channel (w = q * max|w| / L, L = 127, else 63 or 31 to stay "
    "under 5 MB; stored as int8), other tensors float16, safetensors compressed with gzip"
)


class ReferenceError(DataError):
    """The reference checkpoint file is missing, truncated or not one :func:`save_reference` wrote."""


@dataclass(frozen=True)
class ReferenceRecipe:
    """How the reference checkpoint is trained: the paper's three stages in miniature (backbone;
    refinement initialisation with the backbone frozen and the head at ``head_lr_factor`` x lr;
    full model, backbone at lr / 4), L1 + L2 loss (not the paper's L2), cosine schedules;
    ``semantic_dropout`` of the frames trained with the fallback semantic map (so the model also works
    without a segmenter).
    ``seed`` is the training seed (batch order, augmentation, initialisation); the scenes come
    from ``data_seed`` for every training seed."""

    data_seed: int = 1000
    train_frames: int = 400
    val_frames: int = 16
    size: tuple[int, int] = (96, 320)
    style: str = "realistic"
    width: float = 0.125
    batch_size: int = 4
    lr: float = 2e-3
    backbone_steps: int = 600
    refine_init_steps: int = 60
    full_steps: int = 200
    head_lr_factor: float = 5.0
    loss: str = "l1+l2"
    semantic_dropout: float = 0.0
    seed: int = 0

    def variant(self, width: float, **fields: object) -> VariantRecipe:
        """This recipe for :func:`~semattnet.apps.experiment.train_variant` at ``width`` (``fields``: further
        :class:`~semattnet.training.TrainConfig` fields)."""
        return VariantRecipe(
            self.backbone_steps,
            self.full_steps,
            self.size,
            width,
            self.batch_size,
            self.lr,
            self.seed,
            refine_init_steps=self.refine_init_steps,
            head_lr_factor=self.head_lr_factor,
            loss=self.loss,
            semantic_dropout=self.semantic_dropout,
            fields=fields,
        )


REFERENCE_RECIPE = ReferenceRecipe()


def encode_reference(model: Any, info: dict[str, object], levels: int) -> bytes:  # a SemAttNet (its .config)
    """The file's bytes: the model packed (:func:`semattnet.weights.packed.encode_packed`) with ``info``."""
    return encode_packed(model.state_dict(), model.config.to_dict(), info, levels)


def choose_levels(model: nn.Module) -> int:
    """The largest of :data:`LEVELS` whose file stays under :data:`MAX_BYTES` (with room for the info)."""
    for levels in LEVELS:
        if len(encode_reference(model, {}, levels)) < MAX_BYTES - 20_000:
            return levels
    raise ReferenceError(f"reference checkpoint: over {MAX_BYTES} bytes even at {LEVELS[-1]} levels")


def save_reference(model: nn.Module, path: Path, info: dict[str, object], levels: int = 127) -> Path:
    """Write ``model`` packed at ``levels`` (:func:`semattnet.weights.packed.save_packed`) with ``info``."""
    return save_packed(model, path, info, levels)


def load_reference(path: Path | None = None) -> tuple[nn.Module, dict[str, Any]]:
    """The reference model (eval mode, float32 on the CPU) and its recorded info (recipe, command, metrics)."""
    path = Path(path) if path is not None else REFERENCE_PATH
    try:
        ckpt = load_checkpoint(path)
        if ckpt.format != "packed":
            raise CheckpointError(f"{path}: a {ckpt.format} checkpoint, not packed weights")
    except CheckpointError as exc:
        why = str(exc).removeprefix(f"{path}: ")
        raise ReferenceError(f"{path}: not a readable demo reference checkpoint ({why})") from None
    model = build_model(config=ckpt.config)
    load_weights(model, ckpt)
    return model.eval(), dict(ckpt.extra.get("info") or {})


def reference_for(recipe: ReferenceRecipe, seed: int) -> Path | None:
    """The shipped reference of training seed ``seed`` when its record says it was trained by ``recipe`` (all but
    the seed; a field the record lacks counts as :data:`REFERENCE_RECIPE`'s), else None: a run that needs the
    model ``recipe`` trains reads it instead of training it again. It ships quantised: its scores are the file's."""
    path = shipped_references().get(seed)
    if path is None:
        return None
    recorded = dict(load_checkpoint(path).extra.get("info") or {}).get("recipe", {})
    plain = lambda v: list(v) if isinstance(v, tuple) else v  # noqa: E731 (JSON keeps tuples as lists)
    defaults = asdict(REFERENCE_RECIPE)
    same = all(plain(recorded.get(k, defaults[k])) == plain(v) for k, v in asdict(recipe).items() if k != "seed")
    return path if same and recorded.get("seed") == seed else None


def train_reference(
    work: Path,
    target: Path | None = None,
    recipe: ReferenceRecipe = REFERENCE_RECIPE,
    device: torch.device | str = "cpu",
    log: Callable[[str], None] = print,
) -> Path:
    """Train the reference checkpoint in ``work`` (data and runs) and write it to ``target``
    (default: the shipped file of ``recipe.seed``); returns ``target``."""
    target = Path(target) if target is not None else reference_path(recipe.seed)
    start = time.perf_counter()
    r = recipe
    log(f"reference: {r.train_frames} training scenes (data seed {r.data_seed}) at {r.size[0]}x{r.size[1]} ...")
    held = make_synthetic(work / "data", r.train_frames, r.val_frames, r.size, r.data_seed, style=r.style)
    ckpt = train_variant(work / "run", work / "data", r.variant(r.width, branches=3), torch.device(device), log=log)
    return package_reference(ckpt, held, target, r, time.perf_counter() - start, log, reference_command(r))


def reference_command(recipe: ReferenceRecipe) -> str:
    """The command that trains ``recipe``'s reference (its seed: one of ``--seeds``)."""
    dropout = f" --semantic-dropout {recipe.semantic_dropout:g}" if recipe.semantic_dropout else ""
    return f"{REFERENCE_COMMAND}{dropout}"


def package_reference(
    weights: Path,
    held: HeldOut,
    target: Path,
    recipe: ReferenceRecipe = REFERENCE_RECIPE,
    train_seconds: float | None = None,
    log: Callable[[str], None] = print,
    command: str = REFERENCE_COMMAND,
) -> Path:
    """Quantise the trained ``weights`` (a training run's file; any registered architecture), score what ships
    on ``held`` beside the classical completion, and write it with its record (``command``: what trained it)
    to ``target``."""
    trained = load_checkpoint(weights)
    model = build_model(config=trained.config)
    load_weights(model, trained)
    levels = choose_levels(model)
    load_weights(model, dequantise(quantise(model.state_dict(), levels)))  # score exactly what ships
    cpu = torch.device("cpu")
    preds = {n: o["refined_depth"] for n, o in complete_held_out(model, held, cpu).items()}
    blind = {n: o["refined_depth"] for n, o in complete_held_out(model, held, cpu, fallback_semantic).items()}
    classical = {
        n: complete_classical(s["sparse"][None])[0, 0].numpy() for n, s in zip(held.names, held.samples, strict=True)
    }
    info = {
        "recipe": asdict(recipe),
        "command": command,
        "torch": torch.__version__,
        "machine": machine_line(),
        "levels": levels,
        "train_seconds": None if train_seconds is None else round(train_seconds, 1),
        "val": {
            "reference": _metrics(score_held_out(preds, held)["all"]),
            "reference_fallback_map": _metrics(score_held_out(blind, held)["all"]),
            "classical": _metrics(score_held_out(classical, held)["all"]),
        },
    }
    save_reference(model, target, info, levels)
    log(
        f"reference: written {target} ({target.stat().st_size / 1e6:.2f} MB, {levels} levels); "
        f"own validation scenes: {info['val']}"
    )
    return target


def _metrics(m: dict[str, float]) -> dict[str, float]:
    keys = {"rmse": "rmse_mm", "mae": "mae_mm", "irmse": "irmse_per_km", "imae": "imae_per_km"}
    return {k: round(float(m[src]), 3) for k, src in keys.items()}


def machine_line() -> str:
    """CPU model and core count, one line."""
    import os
    import platform

    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(
            line.split(":", 1)[1].strip()
            for line in Path("/proc/cpuinfo").read_text().splitlines()
            if line.lower().startswith("model name")
        )
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores"


def recipe_notes(recipe: dict[str, Any]) -> list[str]:
    """Plain sentences on how the reference was trained and how that differs from the paper."""
    if not recipe:
        return []
    r = recipe
    return [
        f"Reference checkpoints (shipped, {REFERENCE_NAME.format(seed='S')}, one per training seed "
        f"{', '.join(map(str, REFERENCE_SEEDS))}): trained once with `{REFERENCE_COMMAND}` on "
        f"{r['train_frames']} other synthetic scenes (data seed {r['data_seed']}: none of the held-out scenes), "
        f"{r['size'][0]}x{r['size'][1]}, width {r['width']}, batch {r['batch_size']}: the paper's three stages in "
        f"miniature: {r['backbone_steps']} backbone steps, {r['refine_init_steps']} refinement-initialisation steps "
        f"(backbone frozen, CSPN++ head at {r['head_lr_factor']:g} x the base learning rate {r['lr']:g}, as the "
        f"authors' stage 2 gives the head the larger rate), {r['full_steps']} full-model steps (backbone at a "
        "quarter of the base rate).",
        "Reference deviations from the paper: the loss is L1 + L2 per term (the paper's is L2 alone, which weights "
        "far pixels most), cosine schedules instead of ReduceLROnPlateau, "
        f"{r['backbone_steps'] + r['refine_init_steps'] + r['full_steps']} steps of batch {r['batch_size']} on "
        f"{r['size'][0]}x{r['size'][1]} synthetic scenes instead of 60 + 5 + 95 epochs of 352x1216 KITTI crops, "
        f"width {r['width']:g}, and the weights ship quantised ({REFERENCE_STORAGE}).",
    ]
