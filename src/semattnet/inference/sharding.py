"""Splitting frames over the processes ``torchrun`` starts, with the outputs of one process.

Launched by ``torchrun --nproc_per_node N -m semattnet.cli predict|evaluate ...`` (or any script
that calls :func:`~semattnet.inference.complete_folder`, :func:`~semattnet.inference.raw.complete_kitti_raw`
or :func:`~semattnet.evaluation.evaluate_split` on every rank with the same arguments):

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
The generic collectives (``process_group``, ``on_main``, ``agree``, ``gather_rows``, ``rank_log``) live in
:mod:`semattnet._utils.distributed`; they are re-exported here.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import TypeVar

from semattnet._utils import distributed as dist_utils
from semattnet._utils.distributed import agree, first_error, gather_rows, on_main, process_group, rank_log
from semattnet._utils.outputs import OutputError, staged_outputs

__all__ = ["agree", "gather_rows", "on_main", "process_group", "rank_log", "shard", "shared_stage"]

T = TypeVar("T")


def shard(items: Sequence[T]) -> list[T]:
    """This rank's share of ``items``: every ``world_size()``-th item from position ``rank()``."""
    return list(items[dist_utils.rank() :: dist_utils.world_size()])


def _check_complete(stage: Path, expected: Iterable[str | os.PathLike[str]]) -> None:
    """Raise :class:`OutputError` unless every expected file (relative to the stage) is in ``stage``."""
    missing = [str(p) for p in expected if not (stage / p).is_file()]
    if missing:
        raise OutputError(
            f"{len(missing)} output file(s) missing from {stage} (first: {missing[0]}); with several "
            "nodes --out must be on a file system every node shares"
        )


@contextmanager
def shared_stage(
    out: str | os.PathLike[str], overwrite: bool = False, expected: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[Path]:
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
        first = first_error(error)
        if first is not None:
            raise first
        on_main(_check_complete, Path(stage), expected)
        on_main(keep.close)  # move into place (refusing existing files unless overwrite)
