"""Process-group helpers for ``torchrun`` (single- and multi-node) that also work in one process.

Besides rank / world size and the samplers, the collectives every command uses (in one process each
is a plain call):

* :func:`process_group`: join torchrun's group (gloo: only small messages travel) for a block.
* :func:`on_main`: run on rank 0 only (checks before any work); its value or error reaches every rank.
* :func:`agree`: run on every rank; if it failed anywhere, every rank raises the lowest rank's error.
* :func:`gather_rows`: every rank's rows, merged in order. :func:`rank_log`: ``[rank r/W]`` prefixes.

and for training: :func:`wrap_model` (DDP, optionally SyncBatchNorm), :func:`rank_seed` (each rank its own
random draws) and :func:`check_in_sync` (every rank ended with the same parameters).
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, ParamSpec, TypeVar

import torch
import torch.distributed as dist
from torch import nn
from torch.utils.data import Sampler

from semattnet._errors import SemAttNetError

if TYPE_CHECKING:
    from _typeshed import SupportsRichComparison

T = TypeVar("T")
P = ParamSpec("P")

__all__ = [
    "ResumableSampler",
    "ShardSampler",
    "agree",
    "check_in_sync",
    "cleanup",
    "first_error",
    "gather_rows",
    "init_distributed",
    "is_main",
    "launch_rank",
    "on_main",
    "process_device",
    "process_group",
    "rank",
    "rank_log",
    "rank_seed",
    "world_size",
    "wrap_model",
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


@contextmanager
def process_group() -> Iterator[bool]:
    """Join torchrun's process group (gloo) for the block when launched with ``WORLD_SIZE`` > 1;
    leave it afterwards unless it was joined before. Yields whether several processes take part."""
    joined_before = dist.is_initialized()
    active = init_distributed(torch.device("cpu"))
    try:
        yield active
    finally:
        if active and not joined_before:
            cleanup()


def rank_log(log: Callable[[str], None]) -> Callable[[str], None]:
    """``log`` with ``[rank r/W]`` before each line when several processes run, else ``log``."""
    if world_size() == 1:
        return log
    prefix = f"[rank {rank()}/{world_size()}] "
    return lambda line: log(prefix + line)


def _portable(error: BaseException | None) -> BaseException | None:
    """``error`` if it survives pickling (to send it to the other ranks), else its message as a
    :class:`SemAttNetError` (a ``ValueError``: the CLI prints it as one line)."""
    if error is None:
        return None
    try:
        return pickle.loads(pickle.dumps(error))
    except Exception:
        return SemAttNetError(str(error) or type(error).__name__)


def first_error(error: Exception | None) -> BaseException | None:
    """The error of the lowest rank that had one (collective: every rank calls it)."""
    if world_size() == 1:
        return error
    errors: list[BaseException | None] = [None] * world_size()
    dist.all_gather_object(errors, _portable(error))
    first = next((i for i, e in enumerate(errors) if e is not None), None)
    if first is None:
        return None
    return error if first == rank() else errors[first]  # our own keeps its traceback


def agree(fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """``fn(*args, **kwargs)`` on every rank; if it raised on any rank, every rank raises the error
    of the lowest such rank (collective: every rank must call it)."""
    result: tuple[T] | None = None  # a 1-tuple: fn may return None
    error = None
    try:
        result = (fn(*args, **kwargs),)
    except Exception as exc:
        error = exc
    first = first_error(error)
    if first is not None:
        raise first
    assert result is not None  # no rank failed, so fn returned here
    return result[0]


def on_main(fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """``fn(*args, **kwargs)`` on rank 0 only; every rank returns its result or raises its error
    (collective). The result must pickle."""
    if world_size() == 1:
        return fn(*args, **kwargs)
    box: list[tuple[T] | BaseException | None] = [None]  # rank 0's (result,) or its error
    local = None
    if is_main():
        try:
            box[0] = (fn(*args, **kwargs),)
        except Exception as exc:
            local, box[0] = exc, _portable(exc)
    dist.broadcast_object_list(box, src=0)
    got = box[0]
    if isinstance(got, BaseException):
        raise local if local is not None else got
    assert got is not None  # rank 0 sent its result or its error
    return got[0]


def gather_rows(rows: list[T], key: Callable[[T], SupportsRichComparison]) -> list[T]:
    """Every rank's ``rows``, together and sorted by ``key``, on every rank (collective)."""
    if world_size() == 1:
        return sorted(rows, key=key)
    parts: list[list[T] | None] = [None] * world_size()
    dist.all_gather_object(parts, rows)
    return sorted((row for part in parts for row in part or ()), key=key)


def wrap_model(
    model: nn.Module, device: torch.device, sync_bn: bool = False, find_unused: bool = False
) -> nn.parallel.DistributedDataParallel:
    """``model`` (on ``device``) in DDP, its BatchNorm layers made SyncBatchNorm with ``sync_bn`` (CUDA only);
    ``find_unused``: where the loss may leave trainable parameters without a gradient."""
    if sync_bn:
        model = nn.SyncBatchNorm.convert_sync_batchnorm(model)
    return nn.parallel.DistributedDataParallel(
        model, device_ids=[device.index] if device.type == "cuda" else None, find_unused_parameters=find_unused
    )


def rank_seed(seed: int, rank: int) -> int:
    """The seed of ``rank``'s own random draws: ``seed`` itself on rank 0 (a single process draws as before), moved
    by ``rank`` times an odd constant on the others, so that the low 32 bits (all that torch's CPU generator keeps)
    differ between any two ranks."""
    return seed + rank * 0x9E3779B9


def check_in_sync(model: nn.Module) -> float:
    """The checksum of ``model``'s parameters, the same on every rank (collective), else a ``RuntimeError``
    naming each rank's: DDP's contract, checked at the end of a run."""
    total = torch.stack([p.detach().double().sum() for p in model.parameters()]).sum()
    if world_size() == 1:
        return float(total)
    gathered = [torch.zeros_like(total) for _ in range(world_size())]
    dist.all_gather(gathered, total)
    if any(g != gathered[0] for g in gathered):
        raise RuntimeError(f"ranks diverged: parameter checksums {[float(g) for g in gathered]}")
    return float(total)


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
