"""What a training run records: its result, and the state in its checkpoints that an exact resume restores."""

from __future__ import annotations

from pathlib import Path
from typing import TypedDict

import numpy as np
import numpy.typing as npt
import torch

from semattnet.weights.checkpoint import CheckpointError, load_checkpoint

__all__ = ["TRAIN_FORMAT", "ResumeState", "RngStates", "TrainResult", "TrainState", "read_train_state"]

#: The ``format`` of a training checkpoint's state.
TRAIN_FORMAT = "semattnet-train-v1"


class TrainResult(TypedDict):
    """What :func:`~semattnet.training.trainer.train` returns: where the stage ended and its last validation result."""

    epoch: int
    step: int
    best_rmse_mm: float
    val: dict[str, float] | None


class RngStates(TypedDict, total=False):
    """The random generators' states, restored on resume."""

    torch: torch.Tensor
    numpy: tuple[str, npt.NDArray[np.uint32], int, int, float] | dict[str, object]  # np.random.get_state()
    python: tuple[object, ...]  # random.getstate()
    cuda: list[torch.Tensor]  # only where CUDA is available


class ResumeState(TypedDict):
    """What an exact resume restores from a training checkpoint (``last.pt``)."""

    format: str
    model: dict[str, torch.Tensor]
    train_config: dict[str, object]
    optimizer: dict[str, object]
    scheduler: dict[str, object]
    scaler: dict[str, object]
    rng: RngStates
    epoch: int
    batch_in_epoch: int
    global_step: int
    best_metric: float


class TrainState(ResumeState):
    """A training checkpoint besides its digest: the resume state and the model's config (for ``load_model``)."""

    config: dict[str, object]


def read_train_state(path: Path) -> ResumeState:
    """The state of a training run's checkpoint ``path`` that :meth:`~.trainer.Trainer` resumes from (a one-line
    :class:`~semattnet.weights.checkpoint.CheckpointError` when it is missing or not a training checkpoint)."""
    if not path.is_file():
        raise CheckpointError(f"{path}: nothing to resume from")
    ckpt = load_checkpoint(path)
    extra = ckpt.extra
    if extra.get("format") != TRAIN_FORMAT or ckpt.epoch is None:
        raise CheckpointError(f"{path}: not a semattnet training checkpoint (no optimiser state to resume)")
    return ResumeState(
        format=extra["format"],
        model=ckpt.state_dict,
        train_config=extra["train_config"],
        optimizer=extra["optimizer"],
        scheduler=extra["scheduler"],
        scaler=extra["scaler"],
        rng=extra["rng"],
        epoch=ckpt.epoch,
        batch_in_epoch=extra["batch_in_epoch"],
        global_step=extra["global_step"],
        best_metric=extra["best_metric"],
    )
