"""Data: the dataset registry (KITTI depth completion, NYU Depth v2, VOID), KITTI loaders, transforms,
PNG I/O and synthetic KITTI-like scenes."""

from semattnet._errors import DataError
from semattnet.data.datasets import DATASETS, DatasetSpec, get_dataset
from semattnet.data.io import read_depth, read_image, read_intrinsics, write_depth, write_image
from semattnet.data.kitti.splits import FrameFiles, KittiDepthCompletion, find_frames
from semattnet.data.scans import ProjectionSummary, project_scan_file
from semattnet.data.synthetic.scenes import CITYSCAPES_PALETTE, SyntheticFrame, make_frame
from semattnet.data.synthetic.tree import write_synthetic_kitti
from semattnet.data.transforms import EvalTransform, Sample, TrainTransform

__all__ = [
    "CITYSCAPES_PALETTE",
    "DATASETS",
    "DataError",
    "DatasetSpec",
    "EvalTransform",
    "FrameFiles",
    "KittiDepthCompletion",
    "ProjectionSummary",
    "Sample",
    "SyntheticFrame",
    "TrainTransform",
    "find_frames",
    "get_dataset",
    "make_frame",
    "project_scan_file",
    "read_depth",
    "read_image",
    "read_intrinsics",
    "write_depth",
    "write_image",
    "write_synthetic_kitti",
]
