"""What every scoring of a KITTI split starts with: the split as the benchmark scores it, and the output folder."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from semattnet._utils.outputs import Output, OutputError, check_no_input_overlap, check_outputs
from semattnet.data.kitti import KittiDepthCompletion
from semattnet.data.transforms import EvalTransform

__all__ = ["eval_dataset", "prepare_out", "refuse_listed_inputs"]


def eval_dataset(data: str | os.PathLike[str], split: str, raw_root: str | os.PathLike[str] | None = None,
                 semantic_root: str | os.PathLike[str] | None = None,
                 dataset: str = "kitti-dc") -> KittiDepthCompletion:  # fmt: skip
    """The split as the benchmark scores it: val_select at full size, val cropped to 352x1216
    (small synthetic trees: full frames); another ``dataset`` (:mod:`semattnet.data.datasets`) as its protocol says."""
    if dataset != "kitti-dc":
        from semattnet.data.datasets import get_dataset

        return get_dataset(dataset).dataset(data, split, semantic_root=semantic_root)
    ds = KittiDepthCompletion(data, split, raw_root, semantic_root,
                              transform=EvalTransform(None if split == "val_select" else (352, 1216)))  # fmt: skip
    if split == "val" and min(ds.load(0).size) < 352:
        ds.transform = EvalTransform(None)
    return ds


def prepare_out(out: Path, overwrite: bool, inputs: Sequence[Any] = ()) -> Path:
    """Check ``out``: not inside an input; a non-empty folder needs ``overwrite`` (which replaces
    only the files the evaluation writes). Creates it."""
    check_no_input_overlap(inputs, out_dir=out)
    check_outputs([("", p) for p in inputs], [Output("--out", out, "folder")], overwrite)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise FileExistsError(f"{out} is not empty; pass --overwrite to replace its contents")
    out.mkdir(parents=True, exist_ok=True)
    return out


def refuse_listed_inputs(out: Path | None, ds: Any) -> None:
    """Refuse an ``out`` that holds a file the dataset ``ds`` reads by name from its lists (a VOID list may
    name any path: ``VoidSource.listed_files``), so that ``--overwrite`` never replaces an input."""
    listed = getattr(getattr(ds, "source", None), "listed_files", None)
    if out is None or listed is None:
        return
    root = Path(out).resolve()
    for path in listed():
        if Path(path).resolve().is_relative_to(root):
            raise OutputError(f"output folder {out} holds the input {path} (named by the dataset's lists); "
                              "choose an --out outside the inputs")  # fmt: skip
