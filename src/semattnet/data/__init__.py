"""Data: the dataset registry (KITTI depth completion, NYU Depth v2, VOID), KITTI loaders, transforms and
PNG I/O. The synthetic scenes are :mod:`semattnet.synthetic` (``semattnet.data.make_frame``,
``write_synthetic_kitti``, ``SyntheticFrame`` and ``CITYSCAPES_PALETTE`` answer from there, deprecated, until 0.3)."""

from semattnet._errors import DataError
from semattnet.data.datasets import DATASETS, DatasetSpec, get_dataset
from semattnet.data.io import read_depth, read_image, read_intrinsics, write_depth, write_image
from semattnet.data.kitti.splits import FrameFiles, KittiDepthCompletion, find_frames
from semattnet.data.scans import ProjectionSummary, project_scan_file
from semattnet.data.transforms import EvalTransform, Sample, TrainTransform

__all__ = [
    "DATASETS",
    "DataError",
    "DatasetSpec",
    "EvalTransform",
    "FrameFiles",
    "KittiDepthCompletion",
    "ProjectionSummary",
    "Sample",
    "TrainTransform",
    "find_frames",
    "get_dataset",
    "project_scan_file",
    "read_depth",
    "read_image",
    "read_intrinsics",
    "write_depth",
    "write_image",
]
