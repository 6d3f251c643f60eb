"""Process-group helpers for ``torchrun`` (single- and multi-node) that also work in one process."""

from __future__ import annotations

import os
from collections.abc import Iterator

import torch
import torch.distributed as dist
from torch.utils.data import Sampler

__all__ = [
    "ResumableSampler",
    "ShardSampler",
    "cleanup",
    "init_distributed",
    "is_main",
    "launch_rank",
    "process_device",
    "rank",
    "world_size",
]


def init_distributed(device: torch.device) -> bool:
    """Join the process group when launched by torchrun (``WORLD_SIZE`` > 1); NCCL on CUDA, else gloo."""
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1 or dist.is_initialized():
        return dist.is_initialized()
    dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return True


def process_device(name: str | torch.device = "auto") -> torch.device:
    """The device of this process: ``name`` (``auto``, ``cpu``, ``cuda[:N]``), except that under
    torchrun a CUDA device becomes ``cuda:LOCAL_RANK`` (one GPU per process), made current."""
    from semattnet._utils.device import resolve_device

    device = resolve_device(name)
    if device.type == "cuda" and "LOCAL_RANK" in os.environ:
        device = torch.device("cuda", int(os.environ["LOCAL_RANK"]))
        torch.cuda.set_device(device)
    return device


def launch_rank() -> int:
    """The rank torchrun gave this process (``RANK``), 0 outside torchrun; valid with or without a process group."""
    return int(os.environ.get("RANK", "0")) if int(os.environ.get("WORLD_SIZE", "1")) > 1 else 0


def cleanup() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def rank() -> int:
    return dist.get_rank() if dist.is_initialized() else 0


def world_size() -> int:
    return dist.get_world_size() if dist.is_initialized() else 1


def is_main() -> bool:
    return rank() == 0


class ResumableSampler(Sampler[int]):
    """Shuffled indices for this rank, drawn from (seed, epoch), startable mid-epoch.

    Like ``DistributedSampler`` (the permutation is padded to a multiple of the world size and
    split rank-wise), plus :meth:`start_at` so a resumed run skips the batches it already did
    without loading them.
    """

    def __init__(self, size: int, seed: int = 0, shuffle: bool = True) -> None:
        self.size, self.seed, self.shuffle = size, seed, shuffle
        self.epoch, self.start = 0, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch, self.start = epoch, 0

    def start_at(self, sample: int) -> None:
        self.start = sample

    def _indices(self) -> list[int]:
        if self.shuffle:
            g = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
            order = torch.randperm(self.size, generator=g).tolist()
        else:
            order = list(range(self.size))
        world = world_size()
        total = -(-self.size // world) * world
        order += order[: total - len(order)]
        return order[rank() :: world]

    def __iter__(self) -> Iterator[int]:
        return iter(self._indices()[self.start :])

    def __len__(self) -> int:
        return -(-self.size // world_size()) - self.start


class ShardSampler(Sampler[int]):
    """Every index exactly once across ranks, in order (for evaluation; no padding)."""

    def __init__(self, size: int) -> None:
        self.size = size

    def __iter__(self) -> Iterator[int]:
        return iter(range(rank(), self.size, world_size()))

    def __len__(self) -> int:
        return len(range(rank(), self.size, world_size()))
