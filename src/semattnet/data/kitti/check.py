"""``semattnet data check`` of a KITTI depth completion tree (real or synthetic): the registry entry ``kitti-dc``
through the one check loop of every dataset (:func:`semattnet.data.datasets.check.check_dataset`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

from semattnet.data.datasets import get_dataset

__all__ = ["check_trees"]


def check_trees(
    roots: Sequence[str | os.PathLike[str]],
    raw_root: str | os.PathLike[str] | None = None,
    semantic_root: str | os.PathLike[str] | None = None,
    sample: int | None = None,
    log: Callable[[str], None] = print,
) -> int:
    """Check each KITTI root, reported through ``log``; returns the number of problems."""
    return get_dataset("kitti-dc").check(roots, raw_root, semantic_root, sample, log)
