"""Tiny trees in the real layouts of NYU Depth v2 (sparse-to-dense HDF5) and VOID (folders + list files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image


def nyu_frame(rng: np.random.Generator, h: int = 480, w: int = 640, label: bool = False) -> dict[str, np.ndarray]:
    """One frame's arrays with the real key names, dtypes and shapes (depth: a tilted plane, 1-6 m)."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    depth = (1.0 + 4.0 * xx / w + yy / h + rng.uniform(0, 0.05, (h, w))).astype(np.float32)
    rgb = rng.integers(0, 256, (3, h, w), dtype=np.uint8)
    out = {"rgb": rgb, "depth": depth}
    if label:
        out["label"] = (xx // (w / 4)).astype(np.uint8) + 1  # NYU-40 ids 1..4
    return out


def write_h5(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    import h5py

    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        for k, v in arrays.items():
            f.create_dataset(k, data=v)
    return path


def make_nyu(root: Path, train: int = 2, test: int = 2, seed: int = 0, label: bool = False) -> Path:
    """``root/train/<scene>/<NNNNN>.h5`` and ``root/val/official/<NNNNN>.h5``."""
    rng = np.random.default_rng(seed)
    for i in range(train):
        write_h5(root / "train" / f"scene_{i % 2:02d}" / f"{i + 1:05d}.h5", nyu_frame(rng, label=label))
    for i in range(test):
        write_h5(root / "val" / "official" / f"{i + 1:05d}.h5", nyu_frame(rng, label=label))
    return root


def _png16(path: Path, metres: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(metres * 256).astype(np.uint16)).save(path)


def make_void(
    root: Path, train: int = 2, test: int = 2, seed: int = 0, h: int = 480, w: int = 640, k_format: str = "txt"
) -> Path:
    """``root/void_1500/{split}_*.txt`` listing ``void_1500/data/<seq>/{image,...}/<t>.png`` (release layout)."""
    rng = np.random.default_rng(seed)
    base = root / "void_1500"
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    for split, n in (("train", train), ("test", test)):
        lists: dict[str, list[str]] = {
            r: [] for r in ("image", "sparse_depth", "validity_map", "ground_truth", "intrinsics")
        }
        seq = f"{split}_room"
        seq_dir = base / "data" / seq
        K = np.array([[500.0, 0, w / 2], [0, 500.0, h / 2], [0, 0, 1]])
        k_path = seq_dir / ("K.npy" if k_format == "npy" else "K.txt")
        seq_dir.mkdir(parents=True, exist_ok=True)
        np.save(k_path, K) if k_format == "npy" else np.savetxt(k_path, K)
        for i in range(n):
            stamp = f"{1552097915 + i}.{i:04d}"
            gt = (0.5 + 3.0 * xx / w + yy / h).astype(np.float32)
            valid = rng.random((h, w)) < 1500 / (h * w)
            rel = {
                r: f"void_1500/data/{seq}/{r}/{stamp}.png"
                for r in ("image", "sparse_depth", "validity_map", "ground_truth")
            }
            (root / rel["image"]).parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray(rng.integers(0, 256, (h, w, 3), dtype=np.uint8)).save(root / rel["image"])
            _png16(root / rel["sparse_depth"], np.where(valid, gt, 0))
            _png16(root / rel["ground_truth"], gt)
            (root / rel["validity_map"]).parent.mkdir(parents=True, exist_ok=True)
            Image.fromarray((valid * 255).astype(np.uint8)).save(root / rel["validity_map"])
            for r in rel:
                lists[r].append(rel[r])
            lists["intrinsics"].append(str(k_path.relative_to(root)))
        for r, entries in lists.items():
            (base / f"{split}_{r}.txt").write_text("\n".join(entries) + "\n")
    return root
