"""Frame sources (:class:`semattnet.data.frames.FrameSource`): where
:func:`semattnet.inference.pipeline.complete_frames` gets its frames.

* :class:`FolderSource`: a user's files paired by name (:func:`semattnet.data.pairing.pair_frames`).
* :class:`KittiSplitSource`: a KITTI depth-completion split (:mod:`semattnet.data.kitti`), with ground truth.
* :class:`RawDriveSource`: a KITTI raw drive, each scan projected into the camera with
  :func:`semattnet.geometry.project_points`.
* A ROS bag: :class:`semattnet.robotics.BagSource` (the robot I/O lives in :mod:`semattnet.robotics`).
* :class:`SemanticMaps`: the one choice of a frame's semantic map when its source has none (a segmenter,
  or the fallback map).
"""

from semattnet.data.sources.folder import FolderSource
from semattnet.data.sources.kitti_raw import RawDriveSource
from semattnet.data.sources.kitti_split import KittiSplitSource
from semattnet.data.sources.semantic import SemanticMaps

__all__ = ["FolderSource", "KittiSplitSource", "RawDriveSource", "SemanticMaps"]
