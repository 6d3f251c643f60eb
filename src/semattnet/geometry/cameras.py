"""Reference camera intrinsics (one home for each published set of numbers).

:data:`KITTI_K` is the rectified colour camera 02 of the KITTI raw recordings of 2011-09-26
(``calib_cam_to_cam.txt`` of any ``2011_09_26`` drive, ``P_rect_02[:, :3]``; Geiger et al., "Vision meets
Robotics: The KITTI Dataset", IJRR 2013), for images of 1242 x 375 pixels. Pixel convention as in
:mod:`semattnet.geometry.projection` (pixel centres at integer coordinates).
"""

from __future__ import annotations

import numpy as np

__all__ = ["KITTI_IMAGE_SIZE", "KITTI_K"]

#: KITTI camera 02 intrinsics (pixels) at :data:`KITTI_IMAGE_SIZE` (drive date 2011_09_26).
KITTI_K = np.array([[721.5377, 0.0, 609.5593], [0.0, 721.5377, 172.854], [0.0, 0.0, 1.0]])
#: (width, height) in pixels of the images :data:`KITTI_K` belongs to.
KITTI_IMAGE_SIZE: tuple[int, int] = (1242, 375)
