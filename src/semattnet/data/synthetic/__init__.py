"""Synthetic KITTI-like scenes: ray-cast street scenes with a simulated LiDAR (:mod:`.scenes`), seen by the rig
of a domain (:mod:`.domain`), written as a KITTI depth-completion tree (:mod:`.tree`)."""

from semattnet.data.synthetic.domain import DOMAINS, SOURCE, TARGET, Domain
from semattnet.data.synthetic.scenes import (
    CITYSCAPES_PALETTE,
    KITTI_K,
    MATERIALS,
    SCENE_STYLES,
    SyntheticFrame,
    make_frame,
)
from semattnet.data.synthetic.tree import write_synthetic_kitti

__all__ = [
    "CITYSCAPES_PALETTE",
    "DOMAINS",
    "KITTI_K",
    "MATERIALS",
    "SCENE_STYLES",
    "SOURCE",
    "TARGET",
    "Domain",
    "SyntheticFrame",
    "make_frame",
    "write_synthetic_kitti",
]
