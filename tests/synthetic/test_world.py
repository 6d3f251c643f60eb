"""The randomised synthetic world: streets and rooms, random rigs, LiDAR / random points / depth-camera patterns."""

from __future__ import annotations

import numpy as np
import pytest

from semattnet import InputError
from semattnet.synthetic import WORLD_KINDS, WORLD_PATTERNS, WORLD_SPLITS, make_world_frame, world_seed
from semattnet.synthetic.domain import Pose
from semattnet.synthetic.layout import CAM_HEIGHT, Box
from semattnet.synthetic.materials import CITYSCAPES_PALETTE
from semattnet.synthetic.patterns import LidarRig, depth_edges, depthcam_pattern, lidar_pattern, points_pattern
from semattnet.synthetic.raycast import camera_view
from semattnet.synthetic.world import MIN_SPARSE, random_intrinsics, random_size

SIZE = (64, 112)


@pytest.fixture(scope="module")
def frames() -> dict:  # type: ignore[type-arg]
    """One frame of every kind and pattern (small)."""
    return {(k, p): make_world_frame(7, k, p, SIZE) for k in WORLD_KINDS for p in WORLD_PATTERNS}


def test_every_kind_and_pattern_gives_a_complete_frame(frames: dict) -> None:  # type: ignore[type-arg]
    palette = set(CITYSCAPES_PALETTE.values())
    for (kind, pattern), f in frames.items():
        assert (f.kind, f.pattern) == (kind, pattern) and "fallback_from" not in f.meta
        assert f.rgb.shape == f.semantic.shape == (*SIZE, 3) and f.rgb.dtype == f.semantic.dtype == np.uint8
        assert f.sparse.shape == f.gt.shape == SIZE and f.sparse.dtype == f.gt.dtype == np.float32
        assert f.K.shape == (3, 3) and f.K[0, 0] == f.K[1, 1] > 0
        assert np.all(np.isfinite(f.sparse)) and f.sparse.min() >= 0 and f.gt.min() >= 0
        assert np.count_nonzero(f.sparse) >= MIN_SPARSE
        assert {tuple(c) for c in f.semantic.reshape(-1, 3)} <= palette
        assert f.rgb.std() > 5  # an image, not a flat colour


def test_frames_are_deterministic_in_their_arguments() -> None:
    a, b = make_world_frame(3, size=SIZE), make_world_frame(3, size=SIZE)
    for name in ("rgb", "semantic", "sparse", "gt", "K"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert (a.kind, a.pattern, a.meta) == (b.kind, b.pattern, b.meta)
    again = make_world_frame(3, a.kind, a.pattern, SIZE)  # what was drawn for None does not depend on the rest
    np.testing.assert_array_equal(again.sparse, a.sparse)
    assert not np.array_equal(make_world_frame(4, a.kind, a.pattern, SIZE).rgb, a.rgb)


def test_kinds_and_patterns_are_drawn_when_not_given() -> None:
    drawn = {(f.kind, f.pattern) for f in (make_world_frame(s, size=(32, 48)) for s in range(24))}
    assert {k for k, _ in drawn} == set(WORLD_KINDS)
    assert {p for _, p in drawn} == set(WORLD_PATTERNS)


def test_random_sizes_and_lenses_stay_in_their_ranges() -> None:
    rng = np.random.default_rng(0)
    for _ in range(300):
        h, w = random_size(rng)
        assert 160 <= h <= 384 and 256 <= w <= 1242 and h % 8 == w % 8 == 0 and 1.2 <= w / h <= 4
        K, hfov = random_intrinsics(rng, (h, w))
        assert 50 <= hfov <= 100
        np.testing.assert_allclose(2 * np.rad2deg(np.arctan(w / 2 / K[0, 0])), hfov)
        assert abs(K[0, 2] - (w - 1) / 2) <= 0.1 * w and abs(K[1, 2] - (h - 1) / 2) <= 0.1 * h


def test_indoor_depths_are_room_depths() -> None:
    for seed in range(4):
        f = make_world_frame(seed, "indoor", "depthcam", SIZE)
        assert (f.gt > 0).mean() > 0.8  # walls all round: no sky
        for d in (f.gt, f.sparse):
            assert 0.3 <= d[d > 0].min() and d.max() <= 12.0


def test_street_depths_reach_far_but_not_beyond_80_m() -> None:
    far = 0.0
    for seed in range(3):
        f = make_world_frame(seed, "street", "lidar", SIZE)
        assert f.gt.max() <= 80.0 and f.sparse.max() <= 80.0 and f.gt[f.gt > 0].min() >= 0.5
        far = max(far, float(f.gt.max()))
    assert far > 30.0


def test_points_are_exactly_the_requested_count_of_exact_depths() -> None:
    depth = np.full((40, 60), 3.0)
    depth[:5] = 0.0  # no surface there
    K = np.array([[50.0, 0, 30], [0, 50, 20], [0, 0, 1]])
    sparse, info = points_pattern(depth, K, np.random.default_rng(1), count=500)
    assert np.count_nonzero(sparse) == 500 == info["valid"] and not sparse[:5].any()
    assert np.all(np.abs(sparse[sparse > 0] - 3.0) <= 0.03 * 3.0 + 1e-6)
    sparse, _ = points_pattern(depth, K, np.random.default_rng(1), count=5000)  # more than there are
    assert np.count_nonzero(sparse) == np.count_nonzero(depth)
    f = make_world_frame(2, "indoor", "points", SIZE, count=300)
    assert np.count_nonzero(f.sparse) == 300 == f.meta["sparse"]["count"]  # type: ignore[index]


def _box_before_wall(height: int = 96, width: int = 160) -> tuple[np.ndarray, np.ndarray, list[Box], Pose]:
    """A 1.2 m wide box 4 m before a wall 10 m away, seen level from 1.5 m: depth, K, boxes, camera pose."""
    boxes = [
        Box(np.array([-20.0, -10.0, 10.0]), np.array([20.0, CAM_HEIGHT, 10.5]), "building", np.full(3, 150.0)),
        Box(np.array([-0.6, CAM_HEIGHT - 2.5, 4.0]), np.array([0.6, CAM_HEIGHT, 4.5]), "car", np.full(3, 90.0)),
    ]
    K = np.array([[100.0, 0, (width - 1) / 2], [0, 100.0, (height - 1) / 2], [0, 0, 1]])
    camera = Pose(np.array([0.0, CAM_HEIGHT - 1.5, 0.0]), np.eye(3))
    return camera_view(K, height, width, boxes, camera).depth.reshape(height, width), K, boxes, camera


def test_the_lidar_sees_past_foreground_edges_from_its_mount() -> None:
    depth, K, boxes, camera = _box_before_wall()
    rig = LidarRig("test", 64, (10.0, -30.0), 1.0, (0.5, -0.4, -0.3), 1e-6)
    sparse, info = lidar_pattern(depth, K, np.random.default_rng(0), boxes, camera, rig)
    bleed = (sparse > 0) & (sparse > depth + 0.5)  # background returns where the camera sees the box
    assert bleed.sum() >= 3 and info["beams_in_view"] > 0
    near_edge = depth_edges(depth)
    for _ in range(6):  # grown to 6 pixels around the depth edges
        near_edge = near_edge | np.roll(near_edge, 1, 0) | np.roll(near_edge, -1, 0)
        near_edge = near_edge | np.roll(near_edge, 1, 1) | np.roll(near_edge, -1, 1)
    assert np.all(near_edge[bleed])
    ok = (sparse > 0) & ~bleed
    assert np.median(np.abs(sparse[ok] - depth[ok])) < 0.1


def test_world_lidar_frames_bleed_through_too() -> None:
    bleeds = 0
    for seed in range(6):
        f = make_world_frame(seed, "street", "lidar", (96, 224))
        bleeds += int(np.sum((f.sparse > 0) & (f.gt > 0) & (f.sparse > f.gt + 0.5)))
    assert bleeds > 0


def test_the_depth_camera_loses_depth_edges_and_keeps_the_rest() -> None:
    depth, K, _, _ = _box_before_wall()
    sparse, _ = depthcam_pattern(depth, K, np.random.default_rng(0), max_range=12.0, factor=1)
    edges = depth_edges(depth)
    assert edges.sum() > 20 and not sparse[edges].any()
    kept = sparse > 0
    assert kept.mean() > 0.5 and not kept[depth == 0].any()
    assert np.median(np.abs(sparse[kept] - depth[kept])) < 0.1
    for seed in range(3):  # the world's depth-camera frames too
        f = make_world_frame(seed, "indoor", "depthcam", SIZE)
        assert not f.sparse[depth_edges(f.gt)].any()


def test_split_seeds_never_overlap() -> None:
    seeds = {split: {world_seed(split, i) for i in range(5000)} for split in WORLD_SPLITS}
    assert all(len(s) == 5000 for s in seeds.values())
    assert not seeds["train"] & seeds["heldout"]
    with pytest.raises(InputError):
        world_seed("test", 0)
    with pytest.raises(InputError):
        world_seed("train", -1)


@pytest.mark.parametrize(
    "args",
    [
        {"seed": -1},
        {"seed": 0, "kind": "space"},
        {"seed": 0, "pattern": "radar"},
        {"seed": 0, "size": (8, 8)},
        {"seed": 0, "pattern": "points", "beams": 16},
        {"seed": 0, "beams": 16},
    ],
)
def test_bad_arguments_are_refused(args: dict) -> None:  # type: ignore[type-arg]
    with pytest.raises(InputError):
        make_world_frame(**args)
