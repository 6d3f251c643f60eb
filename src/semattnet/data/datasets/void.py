"""VOID (Wong et al., RA-L 2020; github.com/alexklwong/void-dataset): indoor and outdoor scenes, sparse depth
from visual-inertial odometry at three densities (``void_150``, ``void_500``, ``void_1500`` points per frame).

Layout (the release's): ``void_NNN/{train,test}_{image,sparse_depth,validity_map,ground_truth,intrinsics}.txt``
list one path per frame (relative to the folder holding ``void_NNN``, to ``void_NNN`` itself, or absolute);
images are 640x480 RGB PNGs, sparse depth and ground truth 16-bit PNGs in 1/256 m (KITTI's encoding), the
validity map a PNG whose non-zero pixels mark the sparse points, intrinsics a 3x3 matrix as ``.npy`` or text
(``K.txt``, 9 numbers). Evaluation (KBNet's ``src/kbnet.py``): pixels with gt in 0.2-5.0 m, the predictions as
they are (not clamped to that range; KBNet bounds its network's output instead).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from semattnet._errors import DataError, InputError
from semattnet._utils.bounds import regular_file
from semattnet.data.datasets.frames import MissingSplitError, check_split_in
from semattnet.data.frames import Frame, IndexedSource, SourceInfo, unique_names
from semattnet.data.sources.registry import register_source

#: The splits of VOID's release lists.
VOID_SPLITS = ("train", "test")

__all__ = ["VOID_ROLES", "VOID_VARIANTS", "VoidSource", "read_void_intrinsics"]

#: The list files of a split, by role (``{split}_{role}.txt``); the first three are required.
VOID_ROLES = ("image", "sparse_depth", "ground_truth", "validity_map", "intrinsics")
VOID_VARIANTS = ("void_1500", "void_500", "void_150")
MAX_MEDIAN_M = 100.0


def read_void_intrinsics(path: Path) -> np.ndarray:
    """A (3, 3) pinhole matrix (finite, positive focal lengths) from ``.npy`` or text (9 numbers), naming the
    file on any fault."""
    from semattnet.geometry.projection import check_intrinsics

    regular_file(path, "intrinsics file")
    try:
        K = np.load(path, allow_pickle=False) if path.suffix == ".npy" else np.loadtxt(path)
    except (ValueError, OSError) as exc:
        raise DataError(f"{path}: not a 3x3 intrinsics matrix ({exc})") from None
    if np.asarray(K).size != 9:
        raise DataError(f"{path}: expected a 3x3 intrinsics matrix, got shape {np.asarray(K).shape}")
    try:
        return check_intrinsics(np.asarray(K, dtype=np.float64).reshape(3, 3), str(path))
    except InputError as exc:  # NaN, a zero focal length: the file's fault
        raise DataError(str(exc)) from None


def _read_validity(path: Path) -> np.ndarray:
    from PIL import Image

    regular_file(path, "validity map PNG")
    try:
        with Image.open(path) as img:
            return np.asarray(img)
    except Exception as exc:  # PIL raises many types on corrupt files
        raise DataError(f"{path}: not a readable validity map PNG ({type(exc).__name__}: {exc})") from None


def _folder(root: Path) -> Path:
    """``root`` itself when it holds list files, else its first ``void_NNN`` (1500 first); a root one level
    too high (holding ``void_release/``) is one line naming the folder to pass."""
    if any(root.glob("*_image.txt")):
        return root
    found = next((root / v for v in VOID_VARIANTS if (root / v).is_dir()), None)
    if found is None and root.is_dir():
        below = sorted(c for c in root.iterdir() if c.is_dir() and _holds_release(c))
        if below:
            raise DataError(
                f"{root}: no VOID list files nor {'/'.join(VOID_VARIANTS)} inside, but {below[0]} "
                f"holds them: pass {below[0]}"
            )
    return found or root


def _holds_release(folder: Path) -> bool:
    return any(folder.glob("*_image.txt")) or any((folder / v).is_dir() for v in VOID_VARIANTS)


def _resolve(entry: str, lists: Path) -> Path:
    p = Path(entry)
    if p.is_absolute():
        return p
    candidates = [lists.parent / p, lists / p, lists.parent.parent / p]
    return next((c for c in candidates if c.exists()), candidates[0])


def _read_list(path: Path, lists: Path) -> list[Path]:
    """The entries of one list file, resolved; naming the file (and line) when it is not UTF-8 text of paths."""
    try:
        text = regular_file(path, "VOID list file").read_bytes().decode("utf-8-sig")  # a BOM is not a path
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a UTF-8 text list of paths (byte {exc.start}: {exc.reason})") from None
    entries = []
    for number, line in enumerate(text.splitlines(), 1):
        if "\0" in line:
            raise DataError(f"{path}: line {number} holds a NUL character, not a path")
        if line.strip():
            entries.append(_resolve(line.strip(), lists))
    return entries


@register_source("void", option="--dataset void")
class VoidSource(IndexedSource):
    """The frames of ``split`` (``train`` or ``test``) of a VOID folder (``void_1500``, or a release folder
    holding it), with ground truth and intrinsics; ``semantic_root``: Cityscapes-coloured maps ``NAME.png``
    (e.g. written by ``semattnet segment``), else frames have none (the segmenter or the fallback fills them).

    Raises:
        MissingSplitError: no list file of the split. DataError: a required list file is missing, the lists
        disagree in length, or an entry names a missing file.
    """

    palette: str | None = None  # "cityscapes" when it reads maps from semantic_root

    def __init__(
        self,
        root: str | os.PathLike[str],
        split: str = "test",
        semantic_root: str | os.PathLike[str] | None = None,
        max_frames: int | None = None,
    ) -> None:

        self.split = check_split_in("void", split, VOID_SPLITS)
        self.lists = _folder(Path(root))
        files = {r: self.lists / f"{self.split}_{r}.txt" for r in VOID_ROLES}
        if not any(p.exists() for p in files.values()):  # a FIFO or folder: said by _read_list, not "not found"
            raise MissingSplitError(f"{files['image']}: split list not found (the VOID {self.split} split)")
        for role in VOID_ROLES[:3]:
            if not files[role].exists():
                raise DataError(f"{files[role]}: split file not found (VOID lists {', '.join(VOID_ROLES[:3])})")
        entries = {r: _read_list(p, self.lists) for r, p in files.items() if p.exists()}
        counts = {r: len(v) for r, v in entries.items()}
        if len(set(counts.values())) > 1:
            raise DataError(
                f"{self.lists}: the {self.split} lists differ in length: "
                + ", ".join(f"{files[r].name} {n}" for r, n in counts.items())
            )
        if counts["image"] == 0:
            raise DataError(f"{files['image']}: lists no frames (one path per line expected)")
        n = min(counts["image"], max_frames or counts["image"])
        self.frames = [{r: v[i] for r, v in entries.items()} for i in range(n)]
        named = ((f"{f['image'].parent.parent.name}_{f['image'].stem}", f["image"]) for f in self.frames)
        self.names: Sequence[str] = list(unique_names(named, files["image"]))
        self.by_name = dict(zip(self.names, self.frames, strict=True))
        self.semantic_root = Path(semantic_root) if semantic_root is not None else None
        self.palette = "cityscapes" if self.semantic_root is not None else None

    def load(self, name: str) -> Frame:
        from semattnet.data.io import read_depth, read_image, read_semantic

        f = self.by_name[name]
        rgb, sparse, gt = read_image(f["image"]), read_depth(f["sparse_depth"]), read_depth(f["ground_truth"])
        valid = gt[gt > 0]
        if valid.size and float(np.median(valid)) > MAX_MEDIAN_M:
            raise DataError(
                f"{f['ground_truth']}: median depth {float(np.median(valid)):.1f} m is above "
                f"{MAX_MEDIAN_M:g} m: millimetres? expected 1/256 m units"
            )
        if "validity_map" in f:
            validity = _read_validity(f["validity_map"])
            if validity.shape[:2] != sparse.shape:
                raise DataError(
                    f"{f['validity_map']}: {validity.shape[1]}x{validity.shape[0]}, the sparse map "
                    f"{sparse.shape[1]}x{sparse.shape[0]}"
                )
            sparse = np.where(validity.reshape(sparse.shape[0], sparse.shape[1], -1).max(-1) > 0, sparse, 0)
        K = read_void_intrinsics(f["intrinsics"]) if "intrinsics" in f else None
        paths = {"rgb": f["image"], "sparse": f["sparse_depth"], "gt": f["ground_truth"]}
        sem = None
        if self.semantic_root is not None:
            paths["semantic"] = self.semantic_root / f"{name}.png"
            sem = read_semantic(paths["semantic"])
        return Frame(name, rgb, sparse.astype(np.float32), sem, K=K, gt=gt, paths=paths)

    @property
    def info(self) -> SourceInfo:
        return SourceInfo(self.palette, listed_files=self.listed_files())

    def listed_files(self) -> list[Path]:
        """Every file the lists name for this source's frames (image, depth, validity, intrinsics)."""
        return list(dict.fromkeys(p for f in self.frames for p in f.values()))

    def inputs(self) -> list[Path]:
        """The list folder, every file the lists name (they may lie anywhere: an output must not replace one)
        and the semantic folder."""
        semantic = [self.semantic_root] if self.semantic_root is not None else []
        return [self.lists, *self.listed_files(), *semantic]
