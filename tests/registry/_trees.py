"""Tiny inputs in the real layouts, one builder per registered dataset and source (32x64 frames where the
layout allows it; NYU v2's files are 480x640 by definition, the KITTI raw drive and the bag are the bundled
frame)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from semattnet.data.io import write_depth, write_image
from tests.data._datasets import make_nyu, make_void

SIZE = (32, 64)


def kitti_tree(root: Path) -> Path:
    """A synthetic KITTI depth-completion tree: one frame in train and in each evaluation split."""
    from semattnet.synthetic.tree import write_synthetic_kitti

    write_synthetic_kitti(root, frames=1, size=SIZE, eval_frames=1, workers=1)
    return root


def nyu_tree(root: Path) -> Path:
    """Two test frames (and one train frame) of NYU v2 HDF5 files, with NYU-40 labels."""
    return make_nyu(root, train=1, test=2, label=True)


def void_tree(root: Path) -> Path:
    """Two test frames (and one train frame) of VOID at 32x64."""
    return make_void(root, train=1, test=2, h=SIZE[0], w=SIZE[1])


def folder_frames(root: Path, n: int = 2) -> tuple[Path, Path]:
    """``n`` frames as ``rgb/fNN.png`` and ``sparse/fNN.png`` (a depth of ``10 + i`` metres every 4th pixel)."""
    for i in range(n):
        write_image(root / "rgb" / f"f{i:02d}.png", np.full((*SIZE, 3), 40 * i, np.uint8))
        depth = np.zeros(SIZE, np.float32)
        depth[::4, ::4] = 10.0 + i
        write_depth(root / "sparse" / f"f{i:02d}.png", depth)
    return root / "rgb", root / "sparse"


def sensor_bag(root: Path, n: int = 2) -> Path:
    """The bundled KITTI raw frame ``n`` times, 0.1 s apart, as a ROS 1 bag (scans 3 ms after the images)."""
    from semattnet.data.kitti.raw import RawDrive
    from semattnet.robotics.bags import SensorRecord, write_sensor_bag
    from tests.inference._raw_sample import DRIVE

    frame, t0 = RawDrive(DRIVE, 2).frame("0000000005"), 1_317_000_000 * 10**9
    records = [SensorRecord(frame.image, frame.points, t0 + i * 10**8, t0 + i * 10**8 + 3 * 10**6) for i in range(n)]
    write_sensor_bag(root / "drive.bag", records, frame.calib, fmt="ros1")
    return root / "drive.bag"


def corrupt(path: Path) -> Path:
    """Overwrite ``path`` with bytes no reader accepts (a truncated PNG header and text)."""
    path.write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    return path
