"""``semattnet data check --dataset NAME`` for the datasets read through a frame source (NYU v2, VOID)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from semattnet._errors import DataError
from semattnet.data.check import SplitReport, check_roots, log_report
from semattnet.data.datasets.frames import MissingSplitError

__all__ = ["check_sources", "check_split_source"]


def check_split_source(source: Any, split: str, sample: int | None = None) -> SplitReport:
    """Decode the frames of ``source`` (at most ``sample``, evenly spaced): problems name the files."""
    names = list(source.names)
    rep = SplitReport(split, frames=len(names))
    if sample is not None and sample < len(names):
        names = [names[int(i)] for i in np.linspace(0, len(names) - 1, sample)]
    for name in names:
        try:
            frame = source.load(name)
            rep.sparse_valid.append(float((frame.sparse > 0).mean()))
            if frame.gt is not None:
                rep.gt_valid.append(float((frame.gt > 0).mean()))
        except DataError as exc:
            rep.problems.append(str(exc))
        rep.checked += 1
    return rep


def check_sources(spec: Any, roots: Sequence[str | os.PathLike[str]], semantic_root: Any = None,
                  sample: int | None = None, log: Callable[[str], None] = print) -> int:  # fmt: skip
    """Every split of ``spec`` found under each root; a root without any counts as one problem."""

    def one(root: str | os.PathLike[str]) -> int:
        bad, found, said = 0, False, set()
        for split in spec.splits:
            try:
                source = spec.source(root, split, semantic_root=semantic_root)
            except MissingSplitError:
                continue
            except DataError as exc:
                found = True
                if str(exc) not in said:  # one line for a fault of the root (every split's)
                    log(f"  {split:10s} - {exc}")
                    bad += 1
                said.add(str(exc))
                continue
            found = True
            bad += log_report(check_split_source(source, split, sample), log)
        if not found:
            log(f"  no {spec.title} files found (expected {spec.layout})")
            bad += 1
        return bad

    return check_roots(roots, one, log, heading=lambda root: f"{root} ({spec.name}):")
