"""``--segment SPEC`` with ``--dataset nyuv2|void``: every frame of a split segmented once into a cache folder
of colour-coded maps ``NAME.png`` (the dataset's palette), which then serves as the split's semantic folder.

The folder is ``$SEMATTNET_CACHE/semantic/<dataset>-<key>/`` (the user cache when the variable is unset), ``key``
a digest of the SPEC, the palette and the resolved dataset root: train, evaluate and predict with the same
SPEC on the same root share it, and a map already there is reused (an interrupted run resumes; each map is
written atomically). Delete the folder to segment again (e.g. after replacing a local ``hf:PATH`` model).
The frames are segmented as the protocol shows them (NYU: the 304x228 crop), so maps and frames align.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from semattnet.data.frames import FrameSource

__all__ = ["segment_split", "semantic_cache"]

PathLike = str | os.PathLike[str]


def semantic_cache(dataset: str, root: PathLike, spec: str, palette: str, cache_dir: PathLike | None = None) -> Path:
    """The cache folder of ``spec``'s maps of the frames under ``root`` (module docstring)."""
    from semattnet.cache import get_cache_dir

    key = hashlib.sha256("\n".join([spec, palette, str(Path(root).resolve())]).encode()).hexdigest()[:16]
    return get_cache_dir(cache_dir) / "semantic" / f"{dataset}-{key}"


def segment_split(
    dataset: str,
    root: PathLike,
    splits: tuple[str, ...],
    spec: str,
    device: str = "auto",
    cache_dir: PathLike | None = None,
    log: Callable[[str], None] = print,
    max_frames: int | None = None,
) -> Path:
    """Segment the frames of ``splits`` of ``dataset`` under ``root`` with ``spec`` (a
    :func:`~semattnet.segmentation.load_segmenter` SPEC; its maps in the dataset's palette) into
    :func:`semantic_cache`; returns that folder. The segmenter is loaded only when a map is missing.

    Raises:
        InputError: ``kitti-dc`` (segment its raw images with ``semattnet segment``).
    """
    from semattnet._errors import InputError
    from semattnet.data.datasets import get_dataset

    spec_ = get_dataset(dataset)
    if spec_.make_source is None:
        raise InputError(f"--segment: {dataset} reads its maps from --semantic (make them with `semattnet segment`)")
    out = semantic_cache(spec_.name, root, spec, spec_.palette, cache_dir)
    sources = [spec_.source(root, s, max_frames=max_frames) for s in splits]
    todo = [(src, n) for src in sources for n in src.names if not (out / f"{n}.png").is_file()]
    total = sum(len(src.names) for src in sources)
    if todo:
        _segment(todo, spec, spec_.palette, device, out)
    log(f"semantic maps ({spec}, {spec_.palette}): {len(todo)} segmented, {total - len(todo)} reused in {out}")
    return out


def _segment(todo: Sequence[tuple[FrameSource, str]], spec: str, palette: str, device: str, out: Path) -> None:
    from semattnet._utils.progress import progress
    from semattnet.data.io import write_image
    from semattnet.palette import ids_to_colors
    from semattnet.segmentation.segmenter import load_segmenter

    segmenter = load_segmenter(spec, device, palette=palette)
    with progress(total=len(todo), desc="segmenting", unit="frame", dynamic_ncols=True) as bar:
        for source, name in todo:
            frame = source.load(name)
            ids = segmenter(frame.rgb[None])[0]
            write_image(out / f"{name}.png", ids_to_colors(ids, palette), overwrite=True)
            bar.update(1)
