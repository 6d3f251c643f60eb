"""What every scoring of a split starts with: the split as the benchmark scores it, and the output folder."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from semattnet._utils.outputs import Output, OutputError, check_no_input_overlap, check_outputs
from semattnet.data.datasets import get_dataset

if TYPE_CHECKING:
    from semattnet.data.datasets import SplitDataset
    from semattnet.data.frames import FrameSource

__all__ = ["eval_dataset", "prepare_out", "refuse_listed_inputs"]

PathLike = str | os.PathLike[str]


def eval_dataset(
    data: PathLike,
    split: str,
    raw_root: PathLike | None = None,
    semantic_root: PathLike | None = None,
    dataset: str = "kitti-dc",
) -> SplitDataset:
    """The split as the registry entry's protocol scores it, as a torch Dataset
    (:meth:`~semattnet.data.datasets.DatasetSpec.dataset`: KITTI's val_select at full size, its full val
    cropped to 352x1216 unless the frames are smaller)."""
    return get_dataset(dataset).dataset(data, split, raw_root=raw_root, semantic_root=semantic_root)


def prepare_out(out: Path, overwrite: bool, inputs: Sequence[PathLike | None] = ()) -> Path:
    """Check ``out``: not inside an input; a non-empty folder needs ``overwrite`` (which replaces
    only the files the evaluation writes). Creates it."""
    check_no_input_overlap(inputs, out_dir=out)
    check_outputs([("", p) for p in inputs], [Output("--out", out, "folder")], overwrite)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"{out} is not empty; pass --overwrite to replace its contents")
    out.mkdir(parents=True, exist_ok=True)
    return out


def refuse_listed_inputs(out: Path | None, source: FrameSource) -> None:
    """Refuse an ``out`` that holds a file ``source`` reads by name from its lists (its
    :attr:`~semattnet.data.frames.SourceInfo.listed_files`: a VOID list may name any path), so that
    ``--overwrite`` never replaces an input."""
    if out is None:
        return
    root = Path(out).resolve()
    for path in source.info.listed_files:
        if Path(path).resolve().is_relative_to(root):
            raise OutputError(
                f"output folder {out} holds the input {path} (named by the dataset's lists); "
                "choose an --out outside the inputs"
            )
