"""Where KITTI depth completion keeps each file (spec DATA.md), in one place.

    <kitti>/data_depth_velodyne/{train,val}/<drive>/proj_depth/velodyne_raw/image_0X/<frame>.png
    <kitti>/data_depth_annotated/{train,val}/<drive>/proj_depth/groundtruth/image_0X/<frame>.png
    <raw>/<date>/<drive>/image_0X/data/<frame>.png            (raw RGB; <raw>/<date>/calib_cam_to_cam.txt)
    <semantic>/<date>/<drive>/image_0X/data/<frame>.png       (the authors' semantic maps)
    <kitti>/data_depth_selection/val_selection_cropped/{image,velodyne_raw,groundtruth_depth,intrinsics,semantic}/
        <drive>_{image,velodyne_raw,groundtruth_depth}_<frame>_image_0X.png
    <kitti>/data_depth_selection/test_depth_completion_anonymous/{image,velodyne_raw,intrinsics,semantic}/<id>.png

``<drive>`` is ``<date>_drive_<nnnn>_sync``; ``<date>`` its first 10 characters.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = [
    "SELECTION",
    "SEMANTIC_DIR_NAMES",
    "SPLITS",
    "TEST_DIR",
    "VAL_SELECT_DIR",
    "groundtruth_path",
    "raw_image_path",
    "selection_key",
    "selection_name",
    "semantic_path",
    "velodyne_path",
]

SPLITS = ("train", "val", "val_select", "test")
SELECTION = "data_depth_selection"
VAL_SELECT_DIR = "val_selection_cropped"
TEST_DIR = "test_depth_completion_anonymous"
#: Spellings of the semantic-map folder users have (the authors' code and README disagree).
SEMANTIC_DIR_NAMES = ("semantic", "semantics")


def velodyne_path(root: Path, split: str, drive: str, camera: str, frame: str) -> Path:
    return (
        root
        / "data_depth_velodyne"
        / split
        / drive
        / "proj_depth"
        / "velodyne_raw"
        / f"image_{camera}"
        / f"{frame}.png"
    )


def groundtruth_path(root: Path, split: str, drive: str, camera: str, frame: str) -> Path:
    return (
        root
        / "data_depth_annotated"
        / split
        / drive
        / "proj_depth"
        / "groundtruth"
        / f"image_{camera}"
        / f"{frame}.png"
    )


def raw_image_path(raw_root: Path, drive: str, camera: str, frame: str) -> Path:
    return raw_root / drive[:10] / drive / f"image_{camera}" / "data" / f"{frame}.png"


def semantic_path(semantic_root: Path, drive: str, camera: str, frame: str) -> Path:
    return semantic_root / drive[:10] / drive / f"image_{camera}" / "data" / f"{frame}.png"


def selection_name(drive: str, kind: str, frame: str, camera: str, suffix: str = ".png") -> str:
    """File name in val_selection_cropped, e.g. ``<drive>_velodyne_raw_<frame>_image_02.png``."""
    return f"{drive}_{kind}_{frame}_image_{camera}{suffix}"


#: A val_selection_cropped file name: ``<drive>_<kind>_<frame>_image_0X.png``, ``<kind>`` one of the split's
#: three (the name ``predict --rgb image/`` gives its output is the image's).
_SELECTION_NAME = re.compile(
    r"(\d{4}_\d{2}_\d{2}_drive_\d{4}_sync)_(?:image|velodyne_raw|groundtruth_depth)_(\d+_image_\d\d\.png)"
)


def selection_key(name: str) -> str:
    """The ground truth's name of a val_selection_cropped file name of any kind (``..._image_...``,
    ``..._velodyne_raw_...``, ``..._groundtruth_depth_...``): what pairs a prediction with its ground truth;
    any other name unchanged."""
    m = _SELECTION_NAME.fullmatch(name)
    return f"{m[1]}_groundtruth_depth_{m[2]}" if m else name
