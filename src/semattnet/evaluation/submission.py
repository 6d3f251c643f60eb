"""KITTI test-server submissions: predict the test split, check every file, zip."""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
import zipfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from semattnet._errors import SemAttNetError
from semattnet._utils.atomic import atomic_path, fsync_dir
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs, clean_stale_stages
from semattnet._utils.progress import progress as progress_bar
from semattnet.data.io import clamp_for_png, read_depth, write_depth
from semattnet.data.kitti import KittiDepthCompletion
from semattnet.inference.completer import DepthCompleter
from semattnet.weights.hub import load_model

__all__ = ["KITTI_TEST_FRAMES", "SubmissionError", "write_submission", "write_submission_files"]

KITTI_TEST_FRAMES = 1000


class SubmissionError(SemAttNetError):
    """A submission that would be rejected: wrong count, size or encoding."""


def _read_back(folder: Path, names: list[str], expected: dict[str, tuple[int, int]]) -> int:
    """Re-read every PNG: 16-bit, the right size. Holes (0) are legal: the devkit fills them from their
    neighbours (``interpolateBackground``) before scoring; they are counted and reported in one warning."""
    holes = {}
    for name in names:
        d = read_depth(folder / name)
        if d.shape != expected[name]:
            raise SubmissionError(f"{name}: failed the read-back check (reads back as {d.shape[1]}x{d.shape[0]})")
        if n := int((d == 0).sum()):
            holes[name] = n
    if holes:
        shown = ", ".join(f"{k} ({v})" for k, v in list(holes.items())[:5])
        warnings.warn(f"submission: {sum(holes.values())} hole(s) (0 = no prediction, filled by the devkit) in "
                      f"{len(holes)} file(s): {shown}{' ...' if len(holes) > 5 else ''}", stacklevel=3)  # fmt: skip
    return sum(holes.values())


def _check_replaceable(out: Path, zip_path: Path, expected: dict[str, tuple[int, int]], overwrite: bool) -> None:
    """``out`` and the zip may be replaced only with ``overwrite``, and ``out`` only when it holds
    nothing but submission PNGs: a file the submission does not own is never deleted."""
    if not (out.exists() or zip_path.exists()):
        return
    if not overwrite:
        raise FileExistsError(f"{out} or {zip_path} exists; pass --overwrite to replace them")
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} is a file, not a submission folder; remove it or choose another --out")
    foreign = sorted(p.name for p in out.iterdir() if p.name not in expected) if out.exists() else []
    if foreign:
        raise SubmissionError(f"{out} holds {len(foreign)} file(s) a submission does not write, e.g. "
                              f"{out / foreign[0]}; --overwrite only replaces submission files: "
                              "move them or choose another --out")  # fmt: skip


def _write_checked(predictions: Iterable[tuple[str, np.ndarray]], tmp: Path,
                   expected: dict[str, tuple[int, int]]) -> None:  # fmt: skip
    """Write the predictions into ``tmp`` and check count, names, sizes and encoding."""
    for name, depth in predictions:
        if name not in expected:
            raise SubmissionError(f"unexpected prediction {name!r} (not a test frame)")
        if depth.shape != expected[name]:
            raise SubmissionError(f"{name}: prediction is {depth.shape[1]}x{depth.shape[0]}, "
                                  f"the input is {expected[name][1]}x{expected[name][0]}")  # fmt: skip
        write_depth(tmp / name, clamp_for_png(depth, name))
    written = sorted(p.name for p in tmp.glob("*.png"))
    if written != sorted(expected):
        missing = sorted(set(expected) - set(written))
        raise SubmissionError(f"{len(written)} predictions for {len(expected)} test frames; missing {missing[:5]}")
    _read_back(tmp, written, expected)


def write_submission_files(
    predictions: Iterable[tuple[str, np.ndarray]],
    out: str | Path,
    expected: dict[str, tuple[int, int]],
    overwrite: bool = False,
) -> Path:
    """Write ``(file name, depth)`` pairs as KITTI 16-bit PNGs into ``out`` and zip them.

    Everything goes to a temporary folder first; ``out`` and the zip appear only when the count,
    every name, every size (``expected``: name -> (H, W)) and the encoding check out. Holes (0, negative
    or non-finite depth) are written as 0, which the KITTI devkit fills, and reported in a warning.

    Raises:
        SubmissionError: any check fails (nothing is written).
        FileExistsError: ``out`` exists and ``overwrite`` is not set.
    """
    out = Path(out)
    zip_path = out.with_suffix(".zip")
    _check_replaceable(out, zip_path, expected, overwrite)
    out.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_stages(out.parent, f".{out.name}.p")  # the stage folders of killed submissions
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.p{os.getpid()}.", dir=out.parent))
    try:
        _write_checked(predictions, tmp, expected)
        if out.exists():
            shutil.rmtree(out)  # only submission PNGs (checked above)
        os.replace(tmp, out)
        fsync_dir(out.parent)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    with atomic_path(zip_path) as tmp_zip, zipfile.ZipFile(tmp_zip, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(out.glob("*.png")):
            zf.write(p, arcname=p.name)
    return zip_path


def write_submission(
    weights: str | Path,
    data: str | Path,
    out: str | Path,
    device: str = "auto",
    amp: str = "none",
    expected_frames: int | None = KITTI_TEST_FRAMES,
    overwrite: bool = False,
    semantic_root: str | Path | None = None,
    backend: str = "torch",
) -> Path:
    """Predict the test split (``test_depth_completion_anonymous``) with ``weights`` (a file, folder, registry
    name or URL: :func:`semattnet.weights.hub.load_model`) and write a ready-to-upload zip.

    ``expected_frames`` is KITTI's 1000; pass ``None`` to accept any count (e.g. synthetic data).
    """
    local = Path(weights) if Path(weights).exists() else None  # a name or URL reads a cached download
    check_no_input_overlap([data, semantic_root, local], out_dir=out)
    check_no_input_overlap([data, semantic_root, local], out_files=[Path(out).with_suffix(".zip")])
    check_outputs([("--data", data), ("--semantic-root", semantic_root), ("--weights", local)],
                  [Output("--out", out, "folder"), Output("--out", Path(out).with_suffix(".zip"), "zip")],
                  overwrite)  # fmt: skip
    ds = KittiDepthCompletion(data, "test", semantic_root=semantic_root)
    if expected_frames is not None and len(ds) != expected_frames:
        raise SubmissionError(f"{data}: the test split has {len(ds)} frames, KITTI expects {expected_frames}")
    completer = DepthCompleter(load_model(weights), device=device, amp=amp, backend=backend, inplace=True)
    expected = {f.sparse.name: read_depth(f.sparse).shape for f in ds.frames}

    def predictions() -> Iterable[tuple[str, np.ndarray]]:
        for i in progress_bar(range(len(ds)), desc="test split", leave=False):
            x = ds[i]
            res = completer.run(x["rgb"][None], x["semantic"][None], x["sparse"][None])
            yield ds.frames[i].sparse.name, res.depth[0, 0].cpu().numpy()

    return write_submission_files(predictions(), out, expected, overwrite)
