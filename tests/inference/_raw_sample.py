"""Paths to the bundled KITTI raw frame and a tiny random checkpoint, shared by the raw-drive tests."""

from __future__ import annotations

from pathlib import Path

from tests._helpers import SAMPLE

RAW_DATE = SAMPLE / "kitti_raw" / "2011_09_26"
DRIVE = RAW_DATE / "2011_09_26_drive_0035_sync"
SCAN = DRIVE / "velodyne_points" / "data" / "0000000005.bin"
OXTS = DRIVE / "oxts" / "data" / "0000000005.txt"
IMAGE_02 = DRIVE / "image_02" / "data" / "0000000005.png"


def three_frame_drive(root: Path) -> Path:
    """A copy of the bundled drive under ``root`` (its date folder, calibration included) with three frames:
    the bundled one (5) and two copies of it (6, 7). Returns the drive folder."""
    import shutil

    date = root / RAW_DATE.name
    shutil.copytree(RAW_DATE, date)
    drive = date / DRIVE.name
    for sub, ext in (("image_02", ".png"), ("velodyne_points", ".bin")):
        for i in (6, 7):
            shutil.copy(drive / sub / "data" / f"0000000005{ext}", drive / sub / "data" / f"{i:010d}{ext}")
    return drive


def official_velodyne_raw(camera: str) -> Path:
    return (
        SAMPLE
        / "data_depth_velodyne"
        / "train"
        / "2011_09_26_drive_0035_sync"
        / "proj_depth"
        / "velodyne_raw"
        / f"image_{camera}"
        / "0000000005.png"
    )


def tiny_checkpoint(path: Path) -> Path:
    """A random three-branch SemAttNet at width 0.125, saved as safetensors."""
    import torch

    import semattnet
    from semattnet.weights.checkpoint import save_safetensors

    torch.manual_seed(0)
    return save_safetensors(semattnet.build_model("semattnet", width=0.125).state_dict(), path)
