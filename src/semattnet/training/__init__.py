"""Training: the typed recipe (paper Sec. IV-B), the loss (eqs. 5, 8, 11, 13, 14), the trainer with
exact resume (DDP helpers: semattnet._utils.distributed)."""

from semattnet.training.config import TRAIN_STAGES, TrainConfig
from semattnet.training.losses import semattnet_loss
from semattnet.training.trainer import Trainer, train

__all__ = ["TRAIN_STAGES", "TrainConfig", "Trainer", "semattnet_loss", "train"]
