"""Cameras: reference intrinsics (one home for each published set of numbers) and :class:`CameraInfoData`,
the fields of a ROS ``sensor_msgs/CameraInfo`` (what a bag's frames carry and a bag sink writes back).

:data:`KITTI_K` is the rectified colour camera 02 of the KITTI raw recordings of 2011-09-26
(``calib_cam_to_cam.txt`` of any ``2011_09_26`` drive, ``P_rect_02[:, :3]``; Geiger et al., "Vision meets
Robotics: The KITTI Dataset", IJRR 2013), for images of 1242 x 375 pixels. Pixel convention as in
:mod:`semattnet.geometry.projection` (pixel centres at integer coordinates).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["KITTI_IMAGE_SIZE", "KITTI_K", "CameraInfoData", "parse_intrinsics"]

#: KITTI camera 02 intrinsics (pixels) at :data:`KITTI_IMAGE_SIZE` (drive date 2011_09_26).
KITTI_K = np.array([[721.5377, 0.0, 609.5593], [0.0, 721.5377, 172.854], [0.0, 0.0, 1.0]])
#: (width, height) in pixels of the images :data:`KITTI_K` belongs to.
KITTI_IMAGE_SIZE: tuple[int, int] = (1242, 375)


@dataclass(frozen=True)
class CameraInfoData:
    """The fields of a ``sensor_msgs/CameraInfo`` (what a bag sink writes back).

    Attributes:
        width, height: image size, pixels. K: (3, 3) intrinsics of the raw image. D: distortion coefficients.
        R: (3, 3) rectification rotation. P: (3, 4) projection of the rectified image.
        distortion_model: e.g. ``plumb_bob``. frame_id: the optical frame. stamp_ns: header stamp.
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray
    P: np.ndarray
    distortion_model: str = "plumb_bob"
    frame_id: str = ""
    stamp_ns: int = 0

    @property
    def image_size(self) -> tuple[int, int]:
        """(width, height) pixels."""
        return (self.width, self.height)

    def intrinsics(self, rectified: bool = True) -> np.ndarray:
        """(3, 3) intrinsics: ``P``'s left 3x3 for a rectified image (when ``P`` is set), else ``K``."""
        K: np.ndarray = self.P[:, :3] if rectified and np.any(self.P[:, :3]) else self.K
        return np.array(K)


def parse_intrinsics(text: str) -> np.ndarray:
    """``"fx,fy,cx,cy"`` or ``"kitti"`` (KITTI's camera 02, :data:`KITTI_K`) -> (3, 3) K.

    Raises:
        ValueError: not four numbers; InputError (a ValueError) for NaN / inf / non-positive focal lengths.
    """
    if text.strip().lower() == "kitti":
        return np.array(KITTI_K)
    from semattnet._utils.bounds import check_pinhole

    fx, fy, cx, cy = (float(v) for v in text.split(","))
    check_pinhole(fx, fy, cx, cy, "--K")
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
