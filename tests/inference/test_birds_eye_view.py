"""The bird's-eye view rasteriser."""

from __future__ import annotations

import numpy as np
import pytest

from semattnet.geometry import PointCloud
from semattnet.viz.pointcloud import LIDAR_COLOR, birds_eye_view


def test_a_point_lands_at_its_cell_with_its_colour() -> None:
    # 0.1 m cells: x in [-10, 10) over 200 columns, z in [0, 20) over 100 rows (far at the top)
    cloud = PointCloud(
        np.array([[0.05, 0.0, 5.05], [-9.99, 0.0, 19.99]], np.float32),
        rgb=np.array([[10, 200, 30], [1, 2, 3]], np.uint8),
    )
    bev = birds_eye_view(cloud, size=(100, 200), x_range=(-10, 10), z_range=(0, 20))
    assert bev.shape == (100, 200, 3) and bev.dtype == np.uint8
    assert bev[99 - 25, 100].tolist() == [10, 200, 30]  # column floor(10.05 / 0.1), row 99 - floor(5.05 / 0.2)
    assert bev[0, 0].tolist() == [1, 2, 3]
    assert np.count_nonzero(bev.any(-1)) == 2


def test_highest_point_wins_a_cell_and_lidar_is_drawn_on_top() -> None:
    xyz = np.array([[1.0, 1.0, 10.0], [1.0, -1.5, 10.0], [-3.0, 0.0, 3.0]])  # y down: the second is highest
    cloud = PointCloud(xyz.astype(np.float32), rgb=np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], np.uint8))
    bev = birds_eye_view(cloud, size=(40, 40), x_range=(-10, 10), z_range=(0, 20), lidar=np.array([[-3.0, 0, 3.0]]))
    assert bev[39 - 20, 22].tolist() == [0, 255, 0]
    assert bev[39 - 6, 14].tolist() == list(LIDAR_COLOR)


def test_height_colouring_outside_points_and_default_width() -> None:
    xyz = np.array([[0.0, -2.5, 5.0], [0.0, 1.5, 15.0], [0.0, 0.0, 99.0], [0.0, 0.0, -1.0]])
    bev = birds_eye_view(xyz, size=(50, 100), z_range=(0, 20), color="height")
    assert bev.shape == (50, 100, 3)
    lit = np.argwhere(bev.any(-1))
    assert len(lit) == 2  # the points beyond 20 m and behind the camera are dropped
    assert not np.array_equal(bev[tuple(lit[0])], bev[tuple(lit[1])])  # different heights, different colours
    assert {c for _, c in lit} == {50}  # x_range None: centred, square cells (20 m * 100 / 50 = 40 m wide)


def test_bad_arguments_raise() -> None:
    with pytest.raises(ValueError, match="size"):
        birds_eye_view(np.zeros((1, 3)), size=(0, 10))
    with pytest.raises(ValueError, match="color"):
        birds_eye_view(np.zeros((1, 3)), color="depth")
