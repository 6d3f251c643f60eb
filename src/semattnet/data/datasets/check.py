"""``semattnet data check``: the one loop that checks a tree of any registered dataset (KITTI depth completion,
NYU v2, VOID): every split its entry knows, read through the entry's frame source, found under each root."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.outputs import incomplete_tree
from semattnet._utils.progress import progress as progress_bar
from semattnet.data.datasets.frames import MissingSplitError
from semattnet.data.frames import IndexedSource

__all__ = ["SplitReport", "check_dataset", "check_roots", "check_split_source", "log_report"]

PathLike = str | os.PathLike[str]


class CheckedDataset(Protocol):
    """What the check reads of a registry entry (:class:`~semattnet.data.datasets.DatasetSpec`)."""

    @property
    def name(self) -> str: ...

    @property
    def title(self) -> str: ...

    @property
    def layout(self) -> str: ...

    @property
    def splits(self) -> tuple[str, ...]: ...

    def source(
        self,
        root: PathLike,
        split: str | None = None,
        *,
        semantic_root: PathLike | None = None,
        raw_root: PathLike | None = None,
        max_frames: int | None = None,
        seed: int = 0,
    ) -> IndexedSource: ...


@dataclass
class SplitReport:
    """One split's check: frames found and decoded, problems (each naming a file), valid-pixel fractions."""

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
        return (
            f"{self.split:10s} {self.frames:7d} frames  checked {self.checked:7d}  "
            f"sparse valid {pct(self.sparse_valid)}  gt valid {pct(self.gt_valid)}  {status}"
        )


def check_split_source(
    source: IndexedSource, split: str, sample: int | None = None, progress: bool = True
) -> SplitReport:
    """Decode the frames of ``source`` (at most ``sample``, evenly spaced): problems name the files."""
    names = list(source.names)
    rep = SplitReport(split, frames=len(names))
    if sample is not None and sample < len(names):
        names = [names[int(i)] for i in np.linspace(0, len(names) - 1, sample)]
    for name in progress_bar(names, desc=f"checking {split}", enabled=progress, leave=False):
        try:
            frame = source.load(name)
            rep.sparse_valid.append(float((frame.sparse > 0).mean()))
            if frame.gt is not None:
                rep.gt_valid.append(float((frame.gt > 0).mean()))
        except DataError as exc:
            rep.problems.append(str(exc))
        rep.checked += 1
    return rep


def log_report(rep: SplitReport, log: Callable[[str], None]) -> int:
    """Log one split's summary and at most 20 of its problems; returns the number of problems."""
    log("  " + rep.summary())
    for problem in rep.problems[:20]:
        log(f"    - {problem}")
    if len(rep.problems) > 20:
        log(f"    ... {len(rep.problems) - 20} more")
    return len(rep.problems)


def check_roots(
    roots: Sequence[PathLike],
    check_root: Callable[[PathLike], int],
    log: Callable[[str], None] = print,
    heading: Callable[[PathLike], str] = lambda root: f"{root}:",
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


def check_dataset(
    spec: CheckedDataset,
    roots: Sequence[PathLike],
    raw_root: PathLike | None = None,
    semantic_root: PathLike | None = None,
    sample: int | None = None,
    log: Callable[[str], None] = print,
) -> int:
    """Every split of ``spec`` found under each root, read through its frame source: a split that cannot be
    indexed (an incomplete KITTI frame, a bad list) is one line naming the files, the frames of the others
    decoded (at most ``sample`` per split; at most 20 problems listed per split). A root without any of the
    dataset's files counts as one problem, so does a generated tree cut short. Returns the number of problems."""

    def one(root: PathLike) -> int:
        bad, found, said = 0, False, set()
        for split in spec.splits:
            try:
                source = spec.source(root, split, semantic_root=semantic_root, raw_root=raw_root)
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
