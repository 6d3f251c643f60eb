"""Frame sources (:class:`semattnet.data.frames.FrameSource`): where
:func:`semattnet.inference.pipeline.complete_frames` gets its frames.

* :class:`FolderSource`: a user's files paired by name (:func:`semattnet.data.pairing.pair_frames`).
* :class:`KittiSplitSource`: a KITTI depth-completion split (:mod:`semattnet.data.kitti.splits`), with ground truth.
* :class:`RawDriveSource`: a KITTI raw drive, each scan projected into the camera with
  :func:`semattnet.geometry.project_points`.
* A ROS bag: :class:`semattnet.robotics.BagSource` (the robot I/O lives in :mod:`semattnet.robotics`).

A frame without a semantic map gets one from :class:`semattnet.inference.semantic.SemanticMaps` (a
segmenter, or the fallback map), which knows the completer.
"""

from semattnet.data.sources.folder import FolderSource
from semattnet.data.sources.kitti_split import KittiSplitSource
from semattnet.data.sources.raw_drive import RawDriveSource

__all__ = ["FolderSource", "KittiSplitSource", "RawDriveSource"]
