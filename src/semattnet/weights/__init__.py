"""Weights on disk: reading checkpoints without running their code, loading into models,
conversion to safetensors, and ONNX / TorchScript export."""

from semattnet.weights.checkpoint import (
    Checkpoint,
    CheckpointError,
    StateDictMismatchError,
    UnsafeCheckpointError,
    config_from_state_dict,
    load_checkpoint,
    load_model,
    load_weights,
    save_safetensors,
)

__all__ = [
    "Checkpoint",
    "CheckpointError",
    "StateDictMismatchError",
    "UnsafeCheckpointError",
    "config_from_state_dict",
    "load_checkpoint",
    "load_model",
    "load_weights",
    "save_safetensors",
]
