"""Write synthetic scenes as a KITTI depth completion tree that the KITTI loaders read unchanged.

Splits: ``train`` and ``val`` in the raw-drive layout (drives of up to 10 frames, camera 02),
``val_select`` in ``val_selection_cropped`` style and ``test`` in
``test_depth_completion_anonymous`` style (no ground truth), semantic maps beside them, camera
intrinsics (``calib_cam_to_cam.txt`` per date, one ``.txt`` per selection frame) and a
``scenes.json`` manifest with the scene style and each frame's seed and whether it is shadowed. Frame ``i`` of split
``s`` always gets the same scene for a given seed, whatever the number of worker processes.
"""

from __future__ import annotations

import json
import os
import shutil
import zlib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TypedDict

import numpy as np

from semattnet._utils.outputs import Output, check_outputs, incomplete_tree, mark_tree
from semattnet.data.io import write_depth as _write_depth
from semattnet.data.io import write_image as _write_image
from semattnet.data.kitti import layout
from semattnet.synthetic.domain import Domain, get_domain
from semattnet.synthetic.scenes import check_style, make_frame

__all__ = ["SYNTH_DATE", "scene_seed", "write_synthetic_kitti"]

#: The date in synthetic drive names: clearly not a KITTI recording day.
SYNTH_DATE = "2000_01_01"
_FRAMES_PER_DRIVE = 10
_DRIVE_BASE = {"train": 0, "val": 1000}


def write_fast_depth(path: Path, depth: np.ndarray) -> None:
    """A depth PNG at zlib level 1 (fast; the encoding is unchanged)."""
    _write_depth(path, depth, compress_level=1)  # fast; the encoding is unchanged


def write_fast_image(path: Path, image: np.ndarray) -> None:
    """An image PNG at zlib level 1."""
    _write_image(path, image, compress_level=1)


def scene_seed(seed: int, split: str, index: int) -> int:
    """The scene seed of frame ``index`` of ``split`` in a tree written with ``seed``."""
    return int(zlib.crc32(f"{seed}/{split}/{index}".encode()))


def _write_calib(path: Path, K: np.ndarray) -> None:
    p = np.hstack([K, np.zeros((3, 1))])
    rows = [f"P_rect_0{c}: " + " ".join(f"{v:.6e}" for v in p.ravel()) for c in (0, 1, 2, 3)]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(rows) + "\n")


class SceneManifest(TypedDict):
    """``scenes.json``: how the tree was generated, frames per split, and every frame's entry."""

    generator: str
    style: str
    domain: str
    seed: int
    size: list[int]
    counts: dict[str, int]
    frames: list[dict[str, object]]


#: One frame to write: the tree, the split, the index, the seed, height, width, shadowed (None: at random), style
#: and domain.
_Job = tuple[Path, str, int, int, int, int, bool | None, str, Domain]


def _job(args: _Job) -> dict[str, object]:
    out, split, index, seed, height, width, shadow, style, domain = args
    fseed = scene_seed(seed, split, index)
    fr = make_frame(height, width, seed=fseed, shadow=shadow, style=style, domain=domain)
    entry: dict[str, object] = {"split": split, "index": index, "seed": fseed, "shadowed": fr.shadowed}
    if split in ("train", "val"):
        drive = f"{SYNTH_DATE}_drive_{_DRIVE_BASE[split] + index // _FRAMES_PER_DRIVE:04d}_sync"
        frame = f"{index % _FRAMES_PER_DRIVE:010d}"
        write_fast_depth(layout.velodyne_path(out, split, drive, "02", frame), fr.sparse)
        write_fast_depth(layout.groundtruth_path(out, split, drive, "02", frame), fr.gt)
        write_fast_image(layout.raw_image_path(out / "kitti_raw", drive, "02", frame), fr.rgb)
        write_fast_image(layout.semantic_path(out / "semantic", drive, "02", frame), fr.semantic)
        entry["name"] = f"{drive}_image_02_{frame}"
    else:
        sub = layout.VAL_SELECT_DIR if split == "val_select" else layout.TEST_DIR
        base = out / layout.SELECTION / sub
        if split == "val_select":
            drive, frame = f"{SYNTH_DATE}_drive_{2000 + index // _FRAMES_PER_DRIVE:04d}_sync", f"{index:010d}"
            image_name = layout.selection_name(drive, "image", frame, "02")
            write_fast_depth(
                base / "velodyne_raw" / layout.selection_name(drive, "velodyne_raw", frame, "02"), fr.sparse
            )
            write_fast_depth(
                base / "groundtruth_depth" / layout.selection_name(drive, "groundtruth_depth", frame, "02"), fr.gt
            )
        else:
            image_name = f"{index:010d}.png"
            write_fast_depth(base / "velodyne_raw" / image_name, fr.sparse)
        write_fast_image(base / "image" / image_name, fr.rgb)
        write_fast_image(base / "semantic" / image_name, fr.semantic)
        (base / "intrinsics").mkdir(parents=True, exist_ok=True)
        (base / "intrinsics" / (Path(image_name).stem + ".txt")).write_text(" ".join(f"{v:.6e}" for v in fr.K.ravel()))
        entry["name"] = Path(image_name).stem
    entry["K"] = fr.K.tolist()
    return entry


def check_out_folder(out: Path, overwrite: bool) -> None:
    """A non-empty ``out`` needs ``overwrite``, and then must be a tree of ours (its marker): never a user's."""
    if overwrite:
        check_outputs([], [Output("--out", out, "tree")], overwrite)
    elif out.exists() and any(out.iterdir()):
        cut = incomplete_tree(out)
        if cut is not None:
            raise FileExistsError(cut)
        raise FileExistsError(f"{out} is not empty; pass overwrite=True (--overwrite) to write into it")


def _jobs(
    out: Path,
    frames: int,
    n_eval: int,
    seed: int,
    size: tuple[int, int],
    shadow_fraction: float,
    style: str,
    dom: Domain,
) -> list[_Job]:
    """One job per frame of every split (shadowed on odd frames when ``shadow_fraction`` is 0.5)."""
    jobs = []
    for split, n in (("train", frames), ("val", n_eval), ("val_select", n_eval), ("test", n_eval)):
        for i in range(n):
            shadow = (i % 2 == 1) if shadow_fraction == 0.5 else None
            jobs.append((out, split, i, seed, size[0], size[1], shadow, style, dom))
    return jobs


def _run_jobs(jobs: list[_Job], workers: int | None) -> list[dict[str, object]]:
    """The frames' manifest entries, the jobs spread over ``workers`` processes (default: one per CPU)."""
    workers = workers if workers is not None else min(len(jobs), os.cpu_count() or 1)
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            return list(pool.map(_job, jobs, chunksize=4))
    return [_job(j) for j in jobs]


def write_synthetic_kitti(
    out: str | os.PathLike[str],
    frames: int = 100,
    size: tuple[int, int] = (352, 1216),
    seed: int = 0,
    eval_frames: int | None = None,
    workers: int | None = None,
    overwrite: bool = False,
    shadow_fraction: float = 0.5,
    style: str = "ideal",
    domain: str | Domain = "source",
) -> SceneManifest:
    """Generate ``frames`` training frames and ``eval_frames`` frames for each of val,
    val_select and test (default ``max(2, frames // 5)``) under ``out``.

    Every frame alternates shadowed / unshadowed deterministically when ``shadow_fraction`` is
    0.5 (exactly half of each split); otherwise each frame is shadowed with that probability.
    ``style`` is a scene style of :data:`~semattnet.synthetic.scenes.SCENE_STYLES`, ``domain`` the rig and
    look (:mod:`semattnet.synthetic.domain`; ``"source"``, the default, is the original generator's).

    Returns the manifest (also written to ``out/scenes.json``). The tree's completion marker
    (:data:`semattnet._utils.outputs.TREE_MARKER`) is written first as "started" and last as "complete".

    Raises:
        FileExistsError: ``out`` holds files and ``overwrite`` is not set.
        OutputError: ``overwrite`` and ``out`` holds files but no tree of ours (no marker).
        InputError: unknown ``style`` or ``domain``.
    """
    check_style(style)
    dom = get_domain(domain)
    out = Path(out)
    check_out_folder(out, overwrite)
    height, width = size
    n_eval = max(2, frames // 5) if eval_frames is None else eval_frames
    jobs = _jobs(out, frames, n_eval, seed, size, shadow_fraction, style, dom)
    if overwrite and out.exists():
        for sub in ("data_depth_velodyne", "data_depth_annotated", "kitti_raw", "semantic", layout.SELECTION):
            shutil.rmtree(out / sub, ignore_errors=True)
    mark_tree(out, "synth", False, resume=f"run synth again into {out} with --overwrite (overwrite=True)")
    entries = _run_jobs(jobs, workers)
    K0 = np.array(entries[0]["K"])
    _write_calib(out / "kitti_raw" / SYNTH_DATE / "calib_cam_to_cam.txt", K0)  # train and val drives share it
    manifest: SceneManifest = {
        "generator": "semattnet.synthetic.scenes",
        "style": style,
        "domain": dom.name,
        "seed": seed,
        "size": [height, width],
        "counts": {s: sum(e["split"] == s for e in entries) for s in layout.SPLITS},
        "frames": [{k: v for k, v in e.items() if k != "K"} for e in entries],
    }
    (out / "scenes.json").write_text(json.dumps(manifest, indent=1))
    mark_tree(out, "synth", True)
    return manifest
