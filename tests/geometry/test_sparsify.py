from __future__ import annotations

import numpy as np
import pytest

from semattnet.data.io import DataError
from semattnet.geometry import beam_ids, keep_beams, keep_random, keep_row_bands, project_points, read_kitti_calibration

from .conftest import RAW_DATE


def test_beam_ids_on_the_real_scan(scan: np.ndarray) -> None:
    ids = beam_ids(scan)
    counts = np.bincount(ids, minlength=64)
    assert ids.max() == 63 and counts.min() > 1000  # 64 well-populated rings (1117..2051 points)
    el = np.degrees(np.arctan2(scan[:, 2], np.hypot(scan[:, 0], scan[:, 1])))
    medians = np.array([np.median(el[ids == b]) for b in range(64)])
    assert np.all(np.diff(medians) < 0)  # beam 0 is the top one, then downwards
    assert 2 < medians[0] < 3.5 and -25 < medians[-1] < -23  # HDL-64E: ~+2 to -24.8 degrees
    by_elevation = beam_ids(scan, method="elevation", origin_height=0.2)
    assert (by_elevation == ids).mean() > 0.9
    shuffled = scan[np.random.default_rng(0).permutation(len(scan))]
    with pytest.raises(DataError, match="scan order gives"):
        beam_ids(shuffled, method="order")
    assert beam_ids(shuffled).max() == 63  # "auto" falls back to elevation


@pytest.mark.parametrize("keep", [32, 16, 8])
def test_keep_beams(scan: np.ndarray, keep: int) -> None:
    kept = keep_beams(scan, keep)
    assert abs(len(kept) / len(scan) - keep / 64) < 0.02
    ids = beam_ids(scan)
    assert np.array_equal(kept, scan[ids % (64 // keep) == 0])
    with pytest.raises(ValueError, match="must divide"):
        keep_beams(scan, 24)


def test_keep_random_is_deterministic(scan: np.ndarray) -> None:
    a, b, c = keep_random(scan, 0.25, seed=1), keep_random(scan, 0.25, seed=1), keep_random(scan, 0.25, seed=2)
    assert len(a) == round(0.25 * len(scan)) and np.array_equal(a, b) and not np.array_equal(a, c)
    cal = read_kitti_calibration(RAW_DATE, "02")
    sparse = project_points(scan, cal.K, cal.T_cam_lidar, cal.image_size)
    m = keep_random(sparse, 0.5, seed=3)
    assert np.count_nonzero(m) == round(0.5 * np.count_nonzero(sparse))
    assert np.all((m == 0) | (m == sparse)) and np.array_equal(m, keep_random(sparse, 0.5, seed=3))


def test_keep_row_bands_approximates_beams(scan: np.ndarray) -> None:
    cal = read_kitti_calibration(RAW_DATE, "02")
    full = project_points(scan, cal.K, cal.T_cam_lidar, cal.image_size)
    truth = project_points(keep_beams(scan, 32), cal.K, cal.T_cam_lidar, cal.image_size) > 0
    n = np.count_nonzero(full)
    rows = keep_row_bands(full, 32)
    assert np.all((rows == 0) | (rows == full))
    assert abs(np.count_nonzero(rows) / n - 0.5) < 0.05
    calib = keep_row_bands(full, 32, K=cal.K, T_cam_lidar=cal.T_cam_lidar)
    agree = np.count_nonzero((calib > 0) & truth) / np.count_nonzero(calib)
    print(f"\nkeep_row_bands(32) with calibration: {agree:.3f} of kept pixels from kept beams")
    assert agree > 0.85
