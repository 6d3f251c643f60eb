"""KITTI test-server submissions: complete the test split through the one frame loop, check every file, zip."""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
import zipfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

from semattnet._errors import SemAttNetError
from semattnet._utils.atomic import atomic_path, fsync_dir
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs, clean_stale_stages
from semattnet._utils.progress import progress as progress_bar
from semattnet.data.io import clamp_for_png, read_depth, write_depth
from semattnet.data.sources import KittiSplitSource
from semattnet.evaluation.evaluate import resolve_completer
from semattnet.inference.contract import CompleterFactory
from semattnet.inference.journal import FRAMES_FILE
from semattnet.inference.pipeline import Completer, OutputSpec, RunOptions, check_frames
from semattnet.inference.sinks import DepthPngSink

__all__ = ["KITTI_TEST_FRAMES", "SubmissionError", "write_submission", "write_submission_files"]

PathLike = str | os.PathLike[str]
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
        warnings.warn(
            f"submission: {sum(holes.values())} hole(s) (0 = no prediction, filled by the devkit) in "
            f"{len(holes)} file(s): {shown}{' ...' if len(holes) > 5 else ''}",
            stacklevel=4,
        )
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
        raise SubmissionError(
            f"{out} holds {len(foreign)} file(s) a submission does not write, e.g. "
            f"{out / foreign[0]}; --overwrite only replaces submission files: "
            "move them or choose another --out"
        )


def _write_predictions(
    predictions: Iterable[tuple[str, np.ndarray]], tmp: Path, expected: dict[str, tuple[int, int]]
) -> None:
    """Write ``(file name, depth)`` pairs into ``tmp``, each a test frame's name and size."""
    for name, depth in predictions:
        if name not in expected:
            raise SubmissionError(f"unexpected prediction {name!r} (not a test frame)")
        if depth.shape != expected[name]:
            raise SubmissionError(
                f"{name}: prediction is {depth.shape[1]}x{depth.shape[0]}, "
                f"the input is {expected[name][1]}x{expected[name][0]}"
            )
        write_depth(tmp / name, clamp_for_png(depth, name))


def _check_stage(tmp: Path, expected: dict[str, tuple[int, int]]) -> None:
    """The stage holds exactly the test frames' PNGs (count and names), each reading back as 16-bit at its
    frame's size (holes warned: :func:`_read_back`)."""
    written = sorted(p.name for p in tmp.glob("*.png"))
    if written != sorted(expected):
        missing, extra = sorted(set(expected) - set(written)), sorted(set(written) - set(expected))
        raise SubmissionError(
            f"{len(written)} predictions for {len(expected)} test frames; missing {missing[:5]}"
            + (f"; not test frames: {extra[:5]}" if extra else "")
        )
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
    return _publish(out, expected, overwrite, lambda tmp: _write_predictions(predictions, tmp, expected))


def _publish(
    out: PathLike, expected: dict[str, tuple[int, int]], overwrite: bool, fill: Callable[[Path], None]
) -> Path:
    """``fill`` a temporary folder beside ``out`` with the PNGs, check them (:func:`_check_stage`), then move it
    into place as ``out`` and zip it: ``out`` and the zip appear only when every check passed."""
    out = Path(out)
    zip_path = out.with_suffix(".zip")
    _check_replaceable(out, zip_path, expected, overwrite)
    out.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_stages(out.parent, f".{out.name}.p")  # the stage folders of killed submissions
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.p{os.getpid()}.", dir=out.parent))
    try:
        fill(tmp)
        _check_stage(tmp, expected)
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
    completer: Completer | CompleterFactory,
    data: PathLike,
    out: PathLike,
    expected_frames: int | None = KITTI_TEST_FRAMES,
    overwrite: bool = False,
    semantic_root: PathLike | None = None,
    inputs: Sequence[PathLike | None] = (),
) -> Path:
    """Complete the test split (``test_depth_completion_anonymous``) with ``completer`` through the one frame
    loop (:func:`~semattnet.inference.pipeline.complete_frames`) and write a ready-to-upload zip.

    ``completer``: a :class:`~semattnet.inference.DepthCompleter` (any
    :class:`~semattnet.inference.pipeline.Completer`), or a
    :class:`~semattnet.inference.contract.CompleterFactory`, built only after every input and output check (as
    :func:`~.evaluate.evaluate_split`). Each prediction is
    written as its frame's sparse file is named, into a stage that :func:`write_submission_files`' checks verify
    before ``out`` and ``OUT.zip`` appear. ``expected_frames`` is KITTI's 1000; pass ``None`` to accept any
    count (e.g. synthetic data). ``inputs``: further files (the weights) that outputs must stay out of.
    """
    given = [data, semantic_root, *inputs]
    zip_path = Path(out).with_suffix(".zip")
    check_no_input_overlap(given, out_dir=out)
    check_no_input_overlap(given, out_files=[zip_path])
    check_outputs(
        [("--data", data), ("--semantic-root", semantic_root), *(("--weights", p) for p in inputs)],
        [Output("--out", out, "folder"), Output("--out", zip_path, "zip")],
        overwrite,
    )
    source = KittiSplitSource(data, "test", semantic_root=semantic_root)
    if expected_frames is not None and len(source) != expected_frames:
        raise SubmissionError(f"{data}: the test split has {len(source)} frames, KITTI expects {expected_frames}")
    rename = {name: source.by_name[name].sparse.name for name in source.names}  # KITTI's names: the sparse file's
    expected = {rename[name]: read_depth(source.by_name[name].sparse).shape for name in source.names}

    def fill(stage: Path) -> None:
        sinks = [DepthPngSink(rename=rename)]
        plan = check_frames(source, sinks, stage, OutputSpec(overwrite=True, inputs=given), RunOptions(on_error="stop"))
        model = resolve_completer(completer, "submit")  # after every check
        with progress_bar(total=len(source), desc="test split", leave=False) as bar:
            plan.run(model, log=lambda _: bar.update())
        (stage / FRAMES_FILE).unlink(missing_ok=True)  # the run's journal: the stage holds the PNGs only

    return _publish(out, expected, overwrite, fill)
