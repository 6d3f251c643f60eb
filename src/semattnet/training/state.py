"""What a training run records: its result, and the state in its checkpoints that an exact resume restores."""

from __future__ import annotations

from typing import TypedDict

import numpy as np
import numpy.typing as npt
import torch

__all__ = ["ResumeState", "RngStates", "TrainResult", "TrainState"]


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
