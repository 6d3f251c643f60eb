"""Typed training configuration with the paper's recipe as defaults (spec TRAINING.md).

Three stages: ``backbone`` (stage 1), ``refine-init`` (CSPN++ head only, backbone frozen) and
``full`` (everything, two learning rates). Fields left as ``None`` take the stage's default.
Every run saves its resolved config as ``config.json`` beside its checkpoints.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from semattnet._errors import InputError
from semattnet.training.losses import LOSSES

__all__ = ["TRAIN_STAGES", "TrainConfig"]

Stage = Literal["backbone", "refine-init", "full"]
TRAIN_STAGES: tuple[str, ...] = ("backbone", "refine-init", "full")

# Authors' values: per-stage epochs, batch, learning rates and plateau patience.
_STAGE_DEFAULTS: dict[str, dict[str, float | None]] = {
    "backbone": {"epochs": 60, "batch_size": 8, "lr": 0.00128, "head_lr": None, "patience": 4},
    "refine-init": {"epochs": 5, "batch_size": 8, "lr": 0.00128, "head_lr": None, "patience": 8},
    "full": {"epochs": 95, "batch_size": 16, "lr": 0.0025298, "head_lr": 0.025298, "patience": 8},
}


@dataclass
class TrainConfig:
    """Everything a training run depends on.

    Attributes:
        stage: ``backbone``, ``refine-init`` or ``full``.
        data: KITTI depth completion root (or a ``semattnet synth`` tree), or the root of ``dataset``.
        dataset: ``kitti-dc`` (default), ``nyuv2`` or ``void`` (:mod:`semattnet.data.datasets`): its reader,
            augmentation, validation metrics and semantic palette (recorded in the model config);
            ``semattnet train --dataset`` also starts from its recipe (epochs, batch, lr, schedule).
        raw_root, semantic_root: optional separate roots (see :class:`~semattnet.data.kitti.KittiDepthCompletion`).
        segment: a segmenter SPEC for ``nyuv2`` / ``void``: the train and validation frames segmented once into
            a cached folder (:mod:`semattnet.segmentation.datasets`) that serves as ``semantic_root``.
        out: run folder (checkpoints, logs, curves).
        init: checkpoint of the previous stage (required for refine-init and full).
        width, refinement_mode, branches, fusion: model options (paper defaults).
        model: the registered architecture (:func:`semattnet.models.list_models`) whose other options
            (encoder, kernel sizes, iterations, ...) the run uses, e.g. ``semattnet_rt_s``; the backbone stage
            builds it without refinement.
        epochs, batch_size, lr, head_lr, patience: ``None`` = the stage's default; batch_size
            is per process (the global batch is batch_size x processes).
        depth_head_init: backbone stage from scratch; ``(scale, shift)`` for the branches' depth
            outputs (see :meth:`SemAttNetBackbone.init_depth_heads`); ``None`` = PyTorch's init,
            as the authors. ``(10, 15)`` makes short runs learn far faster.
        lr_schedule: ``plateau`` (paper: x0.1 after ``patience`` epochs without a better
            validation RMSE) or ``cosine`` (per step, to zero at ``max_steps`` or the last epoch).
        branch_weights: backbone stage; ``w`` per epoch for the branch losses (eq. 14), the
            last value repeating: the authors' (0.2, 0.2, 0.05, 0.05, 0.0).
        crop, random_crop_height, flip, jitter: augmentation (paper: 352x1216, 320 rows, flip, 0.1);
            ``random_crop_height=None`` is 320 rows, or the whole crop when that is smaller.
        semantic_dropout: the share of training frames given the no-segmenter fallback semantic map
            (:func:`~semattnet.data.transforms.drop_semantic`), so the model also works without a
            segmenter; 0 (the paper) by default.
        val_split, val_every, val_max_frames: validation each ``val_every`` epochs on at most
            that many frames (all by default); ``val_split=""`` disables it.
        amp: ``none``, ``bf16`` or ``fp16`` autocast (propagation always in float32).
        grad_checkpointing: recompute ResNet blocks in backward to save activation memory.
        activation_checkpointing: recompute each branch (encoder and decoder) in backward
            (:mod:`semattnet.training.checkpointing`): far less activation memory, one more forward.
        sync_bn: SyncBatchNorm across processes.
        save_every: also checkpoint every N optimiser steps (0 = at epoch ends only).
        keep_last: periodic checkpoints kept besides ``last.pt`` and ``best.pt``.
        max_steps: stop after N steps in total (0 = run all epochs).
        loss: ``l2`` (the paper's masked L2) or ``l1+l2`` (masked L1 + L2 per term; not the paper's,
            used by the demo's reference checkpoint).
    """

    stage: Stage = "backbone"
    data: str = ""
    dataset: str = "kitti-dc"
    raw_root: str | None = None
    semantic_root: str | None = None
    segment: str | None = None
    out: str = "runs/semattnet"
    init: str | None = None
    width: float = 1.0
    branches: int = 3
    fusion: str = "sammafb"
    refinement_mode: str = "authors"
    model: str = "semattnet"
    epochs: int | None = None
    batch_size: int | None = None
    lr: float | None = None
    head_lr: float | None = None
    patience: int | None = None
    lr_schedule: Literal["plateau", "cosine"] = "plateau"
    depth_head_init: tuple[float, float] | None = None
    weight_decay: float = 1e-6
    betas: tuple[float, float] = (0.9, 0.99)
    branch_weights: tuple[float, ...] = (0.2, 0.2, 0.05, 0.05, 0.0)
    crop: tuple[int, int] = (352, 1216)
    random_crop_height: int | None = None
    flip: bool = True
    jitter: float = 0.1
    semantic_dropout: float = 0.0
    val_split: str = "val_select"
    val_every: int = 1
    val_max_frames: int | None = None
    amp: Literal["none", "bf16", "fp16"] = "none"
    grad_checkpointing: bool = False
    activation_checkpointing: bool = False
    sync_bn: bool = False
    workers: int = 4
    seed: int = 0
    save_every: int = 0
    keep_last: int = 3
    max_steps: int = 0
    log_every: int = 10
    device: str = "auto"
    loss: str = "l2"

    def __post_init__(self) -> None:
        if self.stage not in TRAIN_STAGES:
            raise InputError(f"stage must be one of {TRAIN_STAGES}, got {self.stage!r}")
        for key, value in _STAGE_DEFAULTS[self.stage].items():
            if getattr(self, key) is None:
                setattr(self, key, value)
        if self.stage == "full" and self.head_lr is None:
            self.head_lr = self.lr
        if self.amp not in ("none", "bf16", "fp16"):
            raise InputError(f"amp must be none, bf16 or fp16, got {self.amp!r}")
        if self.lr_schedule not in ("plateau", "cosine"):
            raise InputError(f"lr_schedule must be plateau or cosine, got {self.lr_schedule!r}")
        self.betas = tuple(self.betas)  # type: ignore[assignment]
        if self.depth_head_init is not None:
            self.depth_head_init = tuple(self.depth_head_init)  # type: ignore[assignment]
        self.branch_weights = tuple(self.branch_weights)
        self.crop = tuple(self.crop)  # type: ignore[assignment]
        if self.random_crop_height is None:
            self.random_crop_height = min(320, self.crop[0])
        if self.random_crop_height > self.crop[0]:
            raise InputError(f"random_crop_height {self.random_crop_height} exceeds the crop height {self.crop[0]}")
        self._validate()
        from semattnet.data.datasets import get_dataset

        get_dataset(self.dataset)  # a one-line error listing the names
        from semattnet.models.registry import resolve_model_name

        resolve_model_name(self.model)  # a one-line error listing the names

    def _validate(self) -> None:
        """Refuse numbers that cannot train: NaN/inf or non-positive rates, zero or negative counts."""

        def check(name: str, ok: bool, want: str) -> None:
            if not ok:
                raise InputError(f"{name} must be {want}, got {getattr(self, name)!r}")

        def finite(x: object) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

        def whole(x: object, low: int) -> bool:
            return isinstance(x, int) and not isinstance(x, bool) and x >= low

        for name in ("lr", "head_lr", "width"):
            value = getattr(self, name)
            ok = (value is None and name == "head_lr") or (finite(value) and value > 0)
            check(name, ok, "a finite number > 0")
        for name in ("weight_decay", "jitter"):
            check(name, finite(getattr(self, name)) and getattr(self, name) >= 0, "a finite number >= 0")
        for name in ("epochs", "batch_size", "val_every", "log_every", "branches"):
            check(name, whole(getattr(self, name), 1), "a whole number >= 1")
        for name in ("patience", "workers", "seed", "save_every", "keep_last", "max_steps"):
            check(name, whole(getattr(self, name), 0), "a whole number >= 0")
        check("val_max_frames", self.val_max_frames is None or whole(self.val_max_frames, 1), "null or >= 1")
        check("crop", len(self.crop) == 2 and all(whole(v, 1) for v in self.crop), "two whole numbers >= 1")
        check("random_crop_height", whole(self.random_crop_height, 1), "a whole number >= 1")
        check(
            "betas", len(self.betas) == 2 and all(finite(b) and 0 <= b < 1 for b in self.betas), "two numbers in [0, 1)"
        )
        drop = self.semantic_dropout
        check("semantic_dropout", finite(drop) and 0 <= drop <= 1, "a number in [0, 1]")
        check("branch_weights", all(finite(w) and w >= 0 for w in self.branch_weights), "finite numbers >= 0")
        for name in ("sync_bn", "activation_checkpointing"):
            check(name, isinstance(getattr(self, name), bool), "true or false")
        check("loss", self.loss in LOSSES, f"one of {LOSSES}")
        check("segment", self.segment is None or self.semantic_root is None, "null when semantic_root is set")

    def branch_weight(self, epoch: int) -> float:
        if self.stage != "backbone" or not self.branch_weights:
            return 0.0
        return self.branch_weights[min(epoch, len(self.branch_weights) - 1)]

    def to_dict(self) -> dict[str, object]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:  # values from JSON / the CLI: __post_init__ checks them
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise InputError(f"unknown training option(s) {sorted(unknown)}")
        return cls(**data)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> TrainConfig:
        """A config.json, bounded (size, nesting, a regular file: :func:`semattnet._utils.documents.read_document`)."""
        from semattnet._utils.documents import read_document

        data = read_document(path, error=InputError)
        if not isinstance(data, dict):
            raise InputError(f"{path}: expected a JSON object of training options, got {type(data).__name__}")
        return cls.from_dict(data)

    def with_overrides(self, pairs: list[str]) -> TrainConfig:
        """Apply ``key=value`` strings (values parsed as JSON when possible)."""
        data = self.to_dict()
        for pair in pairs:
            key, sep, raw = pair.partition("=")
            key = key.strip().replace("-", "_")
            if not sep or key not in data:
                raise InputError(f"bad override {pair!r}: expected key=value with key in {sorted(data)}")
            try:
                value = json.loads(raw)
            except json.JSONDecodeError:
                value = raw
            data[key] = value
        keys = {p.partition("=")[0].strip().replace("-", "_") for p in pairs}
        if "crop" in keys and "random_crop_height" not in keys:
            data["random_crop_height"] = None  # re-derive it from the new crop
        return TrainConfig.from_dict(data)
