"""Synthetic KITTI-like scenes: ray-cast street scenes with a simulated LiDAR (:mod:`.scenes`), seen by the rig
of a domain (:mod:`.domain`), written as a KITTI depth-completion tree (:mod:`.tree`)."""

from semattnet.synthetic.domain import DOMAINS, SOURCE, TARGET, Domain
from semattnet.synthetic.patterns import (
    PATTERNS,
    LidarRig,
    apply_pattern,
    depthcam_pattern,
    lidar_pattern,
    points_pattern,
)
from semattnet.synthetic.rooms import ROOM_CLASSES, Room, make_room
from semattnet.synthetic.scenes import (
    CITYSCAPES_PALETTE,
    KITTI_K,
    MATERIALS,
    SCENE_STYLES,
    SyntheticFrame,
    make_frame,
)
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.synthetic.world import (
    WORLD_KINDS,
    WORLD_PATTERNS,
    WORLD_SPLITS,
    WorldFrame,
    make_world_frame,
    world_seed,
)

__all__ = [
    "CITYSCAPES_PALETTE",
    "DOMAINS",
    "KITTI_K",
    "MATERIALS",
    "PATTERNS",
    "ROOM_CLASSES",
    "SCENE_STYLES",
    "SOURCE",
    "TARGET",
    "WORLD_KINDS",
    "WORLD_PATTERNS",
    "WORLD_SPLITS",
    "Domain",
    "LidarRig",
    "Room",
    "SyntheticFrame",
    "WorldFrame",
    "apply_pattern",
    "depthcam_pattern",
    "lidar_pattern",
    "make_frame",
    "make_room",
    "make_world_frame",
    "points_pattern",
    "world_seed",
    "write_synthetic_kitti",
]
