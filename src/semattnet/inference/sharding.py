"""Splitting frames over the processes ``torchrun`` starts, with the outputs of one process.

Launched by ``torchrun --nproc_per_node N -m semattnet.cli predict|evaluate ...`` (or any script
that calls :func:`~semattnet.inference.complete_folder`, :func:`~semattnet.inference.raw.complete_kitti_raw`
or :func:`~semattnet.evaluation.evaluate_checkpoint` on every rank with the same arguments):

* :func:`shard`: rank ``r`` of ``W`` takes frames ``r, r + W, r + 2W, ...`` of the full, ordered list.
* :func:`on_main`: checks (existing outputs, outputs inside inputs) run once, on rank 0, before any
  work; their outcome, a value or an error, reaches every rank, so all stop with the same message.
* :func:`agree`: work that may fail on one rank only (a corrupt frame) runs on every rank; if it
  failed anywhere, every rank raises the error of the lowest failing rank.
* :func:`shared_stage`: the staged-output policy (:mod:`semattnet._utils.outputs`) for all ranks at
  once: rank 0 creates one hidden stage folder inside the output folder and sends its path to
  the others; every rank writes its frames there; when every rank succeeded, rank 0 checks that
  every expected file is there and moves them all into place. Any failure, on any rank, leaves
  the output folder unchanged.

The process group carries only these small messages, so it uses gloo even when every rank
runs its model on its own GPU (``cuda:LOCAL_RANK``). In one process every helper is a plain call.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, TypeVar

import torch
import torch.distributed as dist

from semattnet._errors import SemAttNetError
from semattnet._utils import distributed as dist_utils
from semattnet._utils.outputs import OutputError, staged_outputs

__all__ = ["agree", "gather_rows", "on_main", "process_group", "rank_log", "shard", "shared_stage"]

T = TypeVar("T")


@contextmanager
def process_group() -> Iterator[bool]:
    """Join torchrun's process group (gloo) for the block when launched with ``WORLD_SIZE`` > 1;
    leave it afterwards unless it was joined before. Yields whether several processes take part."""
    joined_before = dist.is_initialized()
    active = dist_utils.init_distributed(torch.device("cpu"))
    try:
        yield active
    finally:
        if active and not joined_before:
            dist_utils.cleanup()


def shard(items: Sequence[T]) -> list[T]:
    """This rank's share of ``items``: every ``world_size()``-th item from position ``rank()``."""
    return list(items[dist_utils.rank() :: dist_utils.world_size()])


def rank_log(log: Callable[[str], None]) -> Callable[[str], None]:
    """``log`` with ``[rank r/W]`` before each line when several processes run, else ``log``."""
    if dist_utils.world_size() == 1:
        return log
    prefix = f"[rank {dist_utils.rank()}/{dist_utils.world_size()}] "
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


def _first_error(error: Exception | None) -> BaseException | None:
    """The error of the lowest rank that had one (collective: every rank calls it)."""
    if dist_utils.world_size() == 1:
        return error
    errors: list[BaseException | None] = [None] * dist_utils.world_size()
    dist.all_gather_object(errors, _portable(error))
    first = next((i for i, e in enumerate(errors) if e is not None), None)
    if first is None:
        return None
    return error if first == dist_utils.rank() else errors[first]  # our own keeps its traceback


def agree(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``fn(*args, **kwargs)`` on every rank; if it raised on any rank, every rank raises the error
    of the lowest such rank (collective: every rank must call it)."""
    result, error = None, None
    try:
        result = fn(*args, **kwargs)
    except Exception as exc:
        error = exc
    first = _first_error(error)
    if first is not None:
        raise first
    return result  # type: ignore[return-value]


def on_main(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``fn(*args, **kwargs)`` on rank 0 only; every rank returns its result or raises its error
    (collective). The result must pickle."""
    if dist_utils.world_size() == 1:
        return fn(*args, **kwargs)
    box: list[Any] = [None, None]
    if dist_utils.is_main():
        try:
            box[0] = fn(*args, **kwargs)
        except Exception as exc:
            box[1] = exc
    local = box[1]
    if dist_utils.is_main():
        box[1] = _portable(box[1])
    dist.broadcast_object_list(box, src=0)
    if box[1] is not None:
        raise local if local is not None else box[1]
    return box[0]


def gather_rows(rows: list[T], key: Callable[[T], Any]) -> list[T]:
    """Every rank's ``rows``, together and sorted by ``key``, on every rank (collective)."""
    if dist_utils.world_size() == 1:
        return sorted(rows, key=key)
    parts: list[list[T] | None] = [None] * dist_utils.world_size()
    dist.all_gather_object(parts, rows)
    return sorted((row for part in parts for row in part or ()), key=key)


def _check_complete(stage: Path, expected: Iterable[str | os.PathLike[str]]) -> None:
    """Raise :class:`OutputError` unless every expected file (relative to the stage) is in ``stage``."""
    missing = [str(p) for p in expected if not (stage / p).is_file()]
    if missing:
        raise OutputError(f"{len(missing)} output file(s) missing from {stage} (first: {missing[0]}); with several "
                          "nodes --out must be on a file system every node shares")  # fmt: skip


@contextmanager
def shared_stage(out: str | os.PathLike[str], overwrite: bool = False,
                 expected: Iterable[str | os.PathLike[str]] = ()) -> Iterator[Path]:  # fmt: skip
    """:func:`~semattnet._utils.outputs.staged_outputs` for all ranks (collective): yields the same
    hidden folder inside ``out`` on every rank. After the block, if it succeeded on every rank,
    rank 0 checks that every ``expected`` file (relative path) was written and moves the stage
    into ``out``; else every rank raises the first error and ``out`` is unchanged.

    Inside the block, code that may fail on some ranks only must not be followed by collectives
    unless it runs through :func:`agree`.
    """
    with ExitStack() as keep:  # rank 0 holds the stage; leaving with an error removes it
        stage = on_main(lambda: keep.enter_context(staged_outputs(out, overwrite=overwrite)))
        error = None
        try:
            yield Path(stage)
        except Exception as exc:
            error = exc
        first = _first_error(error)
        if first is not None:
            raise first
        on_main(_check_complete, Path(stage), expected)
        on_main(keep.close)  # move into place (refusing existing files unless overwrite)
