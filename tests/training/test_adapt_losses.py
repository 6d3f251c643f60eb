"""The self-supervised losses of ``semattnet adapt`` on hand-made inputs; the warp on the bundled real stereo pair."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from semattnet._errors import DataError
from semattnet.data.io import read_depth, read_image
from semattnet.data.sources import RawDriveSource
from semattnet.geometry.motion import read_oxts_pose
from semattnet.geometry.warp import inverse_warp
from semattnet.training.adapt.batch import ViewBatch
from semattnet.training.adapt.losses import (
    hide_points,
    photometric_error,
    photometric_loss,
    smoothness_loss,
    sparse_loss,
    ssim_dissimilarity,
)

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "kitti_sample"
DRIVE = SAMPLE / "kitti_raw" / "2011_09_26" / "2011_09_26_drive_0035_sync"
GT = SAMPLE / "data_depth_annotated/train/2011_09_26_drive_0035_sync/proj_depth/groundtruth/image_02/0000000005.png"

F, BASELINE, Z = 100.0, 0.4, 10.0  # a disparity of F * BASELINE / Z = 4 pixels
H, W = 24, 48


def _K(b: int = 1) -> torch.Tensor:
    return torch.tensor([[F, 0.0, W / 2], [0.0, F, H / 2], [0.0, 0.0, 1.0]]).repeat(b, 1, 1)


def _stereo_pair(seed: int = 0) -> tuple[torch.Tensor, ViewBatch]:
    """A textured plane at Z metres seen by a target camera and by a partner BASELINE metres to its right: the
    partner's pixel u' shows what the target's u = u' + 4 does."""
    texture = torch.rand(1, 3, H, W + 4, generator=torch.Generator().manual_seed(seed))
    target, partner = texture[..., :W], texture[..., 4:]
    T = torch.eye(4)
    T[0, 3] = -BASELINE  # target camera -> partner camera: the partner sits at +BASELINE on x
    views = ViewBatch(
        partner[:, None], _K(), torch.zeros(1, 2), _K()[:, None], T[None, None], torch.ones(1, 1, dtype=torch.bool)
    )
    return target, views


def test_a_warp_with_the_true_depth_reproduces_the_target_and_a_wrong_depth_does_not() -> None:
    target, views = _stereo_pair()
    true_loss, mask = photometric_loss(target, torch.full((1, 1, H, W), Z), views)
    assert true_loss < 1e-4
    assert mask[..., :, 6:].float().mean() > 0.95  # every pixel whose window the partner sees is kept
    assert not mask[..., :, :4].any()  # the partner does not see the left columns
    for wrong in (0.5 * Z, 2 * Z):
        assert photometric_loss(target, torch.full((1, 1, H, W), wrong), views)[0] > 0.05


def test_automask_masks_a_static_identical_pair() -> None:
    image = torch.rand(1, 3, H, W, generator=torch.Generator().manual_seed(1))
    views = ViewBatch(
        image[:, None],
        _K(),
        torch.zeros(1, 2),
        _K()[:, None],
        torch.eye(4)[None, None],
        torch.ones(1, 1, dtype=torch.bool),
    )
    loss, mask = photometric_loss(image, torch.full((1, 1, H, W), Z), views)
    assert not mask.any() and loss == 0
    _, unmasked = photometric_loss(image, torch.full((1, 1, H, W), Z), views, automask=False)
    assert unmasked.float().mean() > 0.9


def test_a_crop_warps_as_its_place_in_the_whole_image() -> None:
    _, views = _stereo_pair(2)
    whole, _ = inverse_warp(views.images[:, 0], torch.full((1, 1, H, W), Z), _K(), _K(), views.T_view_cam[:, 0])
    offset = torch.tensor([[10.0, 5.0]])
    crop, _ = inverse_warp(views.images[:, 0], torch.full((1, 1, 8, 16), Z), _K(), _K(), views.T_view_cam[:, 0], offset)
    assert torch.allclose(crop, whole[..., 5:13, 10:26], atol=1e-5)


def test_an_absent_view_counts_for_nothing() -> None:
    target, views = _stereo_pair()
    absent = ViewBatch(views.images, views.K, views.offset, views.K_view, views.T_view_cam, torch.zeros(1, 1).bool())
    loss, mask = photometric_loss(target, torch.full((1, 1, H, W), 2 * Z), absent)
    assert loss == 0 and not mask.any()


def test_ssim_is_zero_for_identical_images_and_the_error_mixes_ssim_and_l1() -> None:
    a = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(3))
    assert ssim_dissimilarity(a, a).abs().max() < 1e-6
    flat = torch.zeros(1, 3, 8, 8)
    mixed = 0.85 * ssim_dissimilarity(flat, flat + 0.5).mean(1, keepdim=True) + 0.15 * 0.5
    assert torch.allclose(photometric_error(flat, flat + 0.5), mixed) and mixed.min() > 0.45  # SSIM ~0: 0.85 / 2


def test_smoothness_is_zero_on_a_constant_map_and_grows_with_image_uncorrelated_edges() -> None:
    flat_image = torch.full((1, 3, 16, 16), 0.5)
    edged_image = flat_image.clone()
    edged_image[..., :, 8:] = 1.0
    constant = torch.full((1, 1, 16, 16), 7.0)
    assert smoothness_loss(constant, flat_image) == 0
    step = constant.clone()
    step[..., :, 8:] = 20.0
    assert smoothness_loss(step, flat_image) > 0
    assert smoothness_loss(step, edged_image) < smoothness_loss(step, flat_image)  # an image edge excuses it
    steps = step.clone()
    steps[..., 8:, :] = 3.0
    assert smoothness_loss(steps, flat_image) > smoothness_loss(step, flat_image)
    assert smoothness_loss(3 * step, flat_image) == pytest.approx(float(smoothness_loss(step, flat_image)), rel=1e-5)


def test_the_hidden_points_are_the_share_asked_of_each_item() -> None:
    gen = torch.Generator().manual_seed(0)
    sparse = torch.rand(2, 1, 100, 200, generator=gen) * 50
    sparse[sparse < 25] = 0  # about half the pixels measured
    kept, hidden = hide_points(sparse, torch.tensor([0.2, 0.3]), torch.Generator().manual_seed(1))
    assert torch.equal(kept + hidden, sparse) and not ((kept > 0) & (hidden > 0)).any()
    for i, share in enumerate((0.2, 0.3)):
        assert float((hidden[i] > 0).sum() / (sparse[i] > 0).sum()) == pytest.approx(share, abs=0.01)


def test_the_sparse_loss_is_l1_at_the_hidden_points_plus_the_weighted_kept_ones() -> None:
    pred = torch.full((1, 1, 2, 2), 10.0)
    kept = torch.tensor([[[[12.0, 0.0], [0.0, 0.0]]]])
    hidden = torch.tensor([[[[0.0, 7.0], [9.0, 0.0]]]])
    assert sparse_loss(pred, kept, hidden, 0.5) == pytest.approx((3 + 1) / 2 + 0.5 * 2)


def test_the_real_stereo_partner_warps_onto_the_frame_with_the_annotated_depth() -> None:
    """KITTI's image_03, warped into image_02 with the official annotated depth, matches image_02 far better than
    with the depth scaled: the partner's pose (the rectified baseline) and the warp's conventions are right."""
    source = RawDriveSource(DRIVE)
    rgb, K = read_image(DRIVE / "image_02" / "data" / "0000000005.png"), source.drive.calib.K
    (view,) = source.views("0000000005")
    assert view.name == "image_03" and view.T_view_cam[0, 3] == pytest.approx(-0.537, abs=0.01)
    gt = torch.from_numpy(read_depth(GT))[None, None]

    def error(scale: float) -> float:
        image = torch.from_numpy(np.array(view.rgb)).permute(2, 0, 1)[None].float() / 255
        depth = torch.where(gt > 0, gt * scale, torch.full_like(gt, 1e3))
        warped, valid = inverse_warp(
            image,
            depth,
            torch.as_tensor(K)[None],
            torch.as_tensor(view.K)[None],
            torch.as_tensor(view.T_view_cam)[None],
        )
        target = torch.from_numpy(np.array(rgb)).permute(2, 0, 1)[None].float() / 255
        keep = valid & (gt > 0)
        return float(((warped - target).abs().mean(1, keepdim=True) * keep).sum() / keep.sum())

    assert error(1.0) < 0.6 * min(error(0.7), error(1.5))


def _with_next_frame(root: Path, metres_east: float) -> Path:
    """A copy of the bundled drive with a frame 6 (frame 5's image) recorded ``metres_east`` further east, both
    packets heading east (roll, pitch, yaw 0)."""
    date = root / "2011_09_26"
    shutil.copytree(DRIVE.parent, date, ignore=shutil.ignore_patterns("*.bin"))
    drive = date / DRIVE.name
    (drive / "velodyne_points" / "data" / "0000000005.bin").symlink_to(DRIVE / "velodyne_points/data/0000000005.bin")
    shutil.copy(drive / "image_02/data/0000000005.png", drive / "image_02/data/0000000006.png")
    fields = (drive / "oxts/data/0000000005.txt").read_text().split()
    fields[3:6] = ["0", "0", "0"]
    (drive / "oxts/data/0000000005.txt").write_text(" ".join(fields))
    lat = math.radians(float(fields[0]))
    fields[1] = repr(float(fields[1]) + math.degrees(metres_east / (6378137.0 * math.cos(lat))))
    (drive / "oxts/data/0000000006.txt").write_text(" ".join(fields))
    return drive


def test_the_next_frame_of_a_drive_is_a_view_posed_by_its_oxts_packets(tmp_path: Path) -> None:
    """Frame 6 taken 1 m further along the heading: its camera is 1 m ahead of frame 5's (camera z forward)."""
    source = RawDriveSource(_with_next_frame(tmp_path, 1.0))
    views = {v.name: v for v in source.views("0000000005")}
    assert sorted(views) == ["0000000006", "image_03"]
    T = views["0000000006"].T_view_cam
    assert np.allclose(T[:3, :3], np.eye(3), atol=1e-6)
    assert np.allclose(T[:3, 3], [0, 0, -1], atol=0.03)
    assert [v.name for v in source.views("0000000006")] == ["0000000005"]  # frame 6 has no image_03


def test_a_malformed_oxts_packet_is_one_line_naming_the_file(tmp_path: Path) -> None:
    (tmp_path / "short.txt").write_text("49.0 8.3 113.4")
    (tmp_path / "pole.txt").write_text(" ".join(["89.9"] + ["0"] * 29))
    for name, message in (("short.txt", "expected 30 finite OXTS fields"), ("pole.txt", "out of range")):
        with pytest.raises(DataError, match=message) as err:
            read_oxts_pose(tmp_path / name)
        assert name in str(err.value)
