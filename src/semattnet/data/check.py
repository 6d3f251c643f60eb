"""Validate a KITTI depth completion tree (real or synthetic): what ``semattnet data check`` runs."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semattnet._utils.outputs import incomplete_tree
from semattnet._utils.progress import progress as progress_bar
from semattnet.data import layout
from semattnet.data.io import DataError
from semattnet.data.kitti import find_frames, load_frame

__all__ = ["SplitReport", "check_roots", "check_tree", "check_trees", "log_report"]


@dataclass
class SplitReport:
    split: str
    frames: int = 0
    checked: int = 0
    problems: list[str] = field(default_factory=list)
    sparse_valid: list[float] = field(default_factory=list)
    gt_valid: list[float] = field(default_factory=list)

    def summary(self) -> str:
        def pct(v: list[float]) -> str:
            return f"{100 * np.mean(v):5.2f} %" if v else "   -   "

        status = "ok" if not self.problems else f"{len(self.problems)} problem(s)"
        return (f"{self.split:10s} {self.frames:7d} frames  checked {self.checked:7d}  "
                f"sparse valid {pct(self.sparse_valid)}  gt valid {pct(self.gt_valid)}  {status}")  # fmt: skip


def check_tree(
    root: str | os.PathLike[str],
    raw_root: str | os.PathLike[str] | None = None,
    semantic_root: str | os.PathLike[str] | None = None,
    sample: int | None = None,
    progress: bool = True,
) -> list[SplitReport]:
    """Check every split present under ``root``: pairing, decoding, sizes, valid-pixel fractions.

    Args:
        sample: decode at most this many frames per split (evenly spaced); all by default.

    Returns:
        One report per split that has any file; a split's ``problems`` name files and faults.
    """
    root = Path(root)
    reports = []
    for split in layout.SPLITS:
        frames, missing = find_frames(root, split, raw_root, semantic_root)
        if not frames and not missing:
            continue
        rep = SplitReport(split, frames=len(frames))
        rep.problems += [f"{name}: missing {', '.join(map(str, paths))}" for name, paths in missing]
        chosen = frames if sample is None or sample >= len(frames) else [
            frames[int(i)] for i in np.linspace(0, len(frames) - 1, sample)]  # fmt: skip
        for f in progress_bar(chosen, desc=f"checking {split}", enabled=progress, leave=False):
            try:
                loaded = load_frame(f)
                rep.sparse_valid.append(float((loaded.sparse > 0).mean()))
                if loaded.gt is not None:
                    rep.gt_valid.append(float((loaded.gt > 0).mean()))
            except DataError as exc:
                rep.problems.append(str(exc))
            rep.checked += 1
        reports.append(rep)
    return reports


def log_report(rep: SplitReport, log: Callable[[str], None]) -> int:
    """Log one split's summary and at most 20 of its problems; returns the number of problems."""
    log("  " + rep.summary())
    for problem in rep.problems[:20]:
        log(f"    - {problem}")
    if len(rep.problems) > 20:
        log(f"    ... {len(rep.problems) - 20} more")
    return len(rep.problems)


def check_roots(
    roots: Sequence[str | os.PathLike[str]],
    check_root: Callable[[str | os.PathLike[str]], int],
    log: Callable[[str], None] = print,
    heading: Callable[[str | os.PathLike[str]], str] = lambda root: f"{root}:",
) -> int:
    """Log ``heading(root)`` and run ``check_root`` (which logs and returns its problem count) on each
    root; a generated tree that was cut short (:func:`semattnet._utils.outputs.incomplete_tree`)
    counts as one problem and is not read further. Returns the total."""
    bad = 0
    for root in roots:
        log(heading(root))
        cut = incomplete_tree(root)
        if cut is not None:
            log(f"  {cut}")
            bad += 1
            continue
        bad += check_root(root)
    return bad


def check_trees(
    roots: Sequence[str | os.PathLike[str]],
    raw_root: str | os.PathLike[str] | None = None,
    semantic_root: str | os.PathLike[str] | None = None,
    sample: int | None = None,
    log: Callable[[str], None] = print,
) -> int:
    """:func:`check_tree` for each root, reported through ``log``; returns the number of problems
    (a root without any KITTI file counts as one, so does a generated tree that was cut short:
    :func:`semattnet._utils.outputs.incomplete_tree`). At most 20 problems are listed per split."""

    def one(root: str | os.PathLike[str]) -> int:
        reports = check_tree(root, raw_root, semantic_root, sample)
        if not reports:
            log("  no KITTI depth completion files found")
            return 1
        return sum(log_report(rep, log) for rep in reports)

    return check_roots(roots, one, log)
