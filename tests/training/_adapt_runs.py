"""What the tests of ``adapt``'s run folder share: the smallest weights there are, and the digests of a run's files."""

from __future__ import annotations

import hashlib
from pathlib import Path

import torch

from semattnet.training.adapt import RUN_FILES
from semattnet.weights.checkpoint import Checkpoint, save_safetensors


def rt_checkpoint(path: Path) -> Path:
    """The real-time S variant at width 0.125 (~11k parameters, seed 0) as safetensors: an adapt run in a second."""
    import semattnet

    torch.manual_seed(0)
    model = semattnet.build_model("semattnet_rt_s", width=0.125)
    return save_safetensors(Checkpoint(path, model.state_dict(), "torch", config=model.config), path)


def digests(out: Path) -> dict[str, str]:
    """sha256 of each of the run's files in ``out``."""
    return {f: hashlib.sha256((out / f).read_bytes()).hexdigest() for f in RUN_FILES if (out / f).is_file()}
