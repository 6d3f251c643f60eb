"""Augmentation: alignment, what jitter may touch, reproducibility across worker counts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from semattnet.data.datasets.frames import IndoorTrainTransform
from semattnet.data.io import DataError
from semattnet.data.kitti.splits import KittiDepthCompletion
from semattnet.data.transforms import (
    EvalTransform,
    Sample,
    TrainTransform,
    bottom_crop,
    color_jitter,
    drop_semantic,
    hflip,
)
from semattnet.palette import UNKNOWN_COLOR
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.training import TrainConfig


def _coded_sample(h: int = 40, w: int = 70) -> Sample:
    """Every array encodes (row, column), so misalignment is visible in any of them."""
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float32)
    code = rows * 1000 + cols
    rgb = np.stack((rows, cols, np.full_like(rows, 128)), -1).astype(np.uint8)
    K = np.array([[50.0, 0, w / 2], [0, 50.0, h / 2], [0, 0, 1]])
    return Sample(rgb=rgb, semantic=rgb.copy(), sparse=code / 256, gt=code / 128, K=K)


@pytest.mark.parametrize("seed", range(12))
def test_train_transform_keeps_everything_aligned(seed: int) -> None:
    s = _coded_sample()
    out = TrainTransform(crop=(32, 64), random_crop_height=24)(s, np.random.default_rng(seed))
    code = out.sparse * 256
    assert out.sparse.shape == (24, 64)
    np.testing.assert_array_equal(out.gt * 128, code)  # gt moved with sparse
    np.testing.assert_array_equal(out.semantic[..., 0], code // 1000)  # rows
    np.testing.assert_array_equal(out.semantic[..., 1], code % 1000)  # columns
    cols = code[0] % 1000
    flipped = cols[0] > cols[-1]
    assert np.all(np.diff(cols) == (-1 if flipped else 1))


def test_flip_happens_about_half_the_time() -> None:
    def flipped(i: int) -> bool:
        out = TrainTransform(crop=(32, 64), random_crop_height=32, jitter=0)(_coded_sample(), np.random.default_rng(i))
        cols = (out.sparse[0] * 256) % 1000
        return bool(cols[0] > cols[-1])

    flips = sum(flipped(i) for i in range(200))
    assert 70 < flips < 130


def _is_fallback(semantic: np.ndarray) -> bool:
    return bool(np.all(semantic == np.asarray(UNKNOWN_COLOR, dtype=semantic.dtype)))


def test_semantic_dropout_replaces_the_map_by_the_fallback_at_its_share() -> None:
    s = _coded_sample()
    drops = [_is_fallback(drop_semantic(s, np.random.default_rng(i), 0.3).semantic) for i in range(400)]
    assert 90 < sum(drops) < 150  # 120 expected
    out = TrainTransform(crop=(32, 64), random_crop_height=24, jitter=0, semantic_dropout=1.0)(
        s, np.random.default_rng(0)
    )
    assert _is_fallback(out.semantic) and out.semantic.shape == (24, 64, 3)
    np.testing.assert_array_equal(out.rgb.astype(np.uint8)[..., 2], 128)  # only the semantic map changed
    indoor = IndoorTrainTransform(samples=None, semantic_dropout=1.0)(s, np.random.default_rng(0))
    assert _is_fallback(indoor.semantic[: s.size[0], : s.size[1]])


def test_no_semantic_dropout_keeps_the_random_stream() -> None:
    """A run without dropout draws nothing more: its augmentations are those of earlier versions."""
    rng, reference = np.random.default_rng(3), np.random.default_rng(3)
    assert drop_semantic(_coded_sample(), rng, 0.0).semantic is not None
    assert rng.random() == reference.random()


@pytest.mark.parametrize("share", [-0.1, 1.5, float("nan")])
def test_train_config_refuses_a_semantic_dropout_outside_0_1(share: float) -> None:
    with pytest.raises(ValueError, match="semantic_dropout"):
        TrainConfig(semantic_dropout=share)


def test_jitter_touches_rgb_only() -> None:
    s = _coded_sample()
    plain = TrainTransform(crop=(32, 64), random_crop_height=32, jitter=0.0)(s, np.random.default_rng(5))
    jittered = TrainTransform(crop=(32, 64), random_crop_height=32, jitter=0.1)(s, np.random.default_rng(5))
    np.testing.assert_array_equal(jittered.semantic, plain.semantic)
    np.testing.assert_array_equal(jittered.sparse, plain.sparse)
    np.testing.assert_array_equal(jittered.gt, plain.gt)
    assert not np.array_equal(jittered.rgb, plain.rgb.astype(np.float32))


def test_color_jitter_factors_bounded() -> None:
    grey = np.full((4, 4, 3), 100, np.uint8)
    for i in range(50):
        out = color_jitter(grey, np.random.default_rng(i), 0.1)
        assert np.all(out >= 90 - 1e-3) and np.all(out <= 110 + 1e-3)  # grey: only brightness acts
    assert color_jitter(np.full((2, 2, 3), 250, np.uint8), np.random.default_rng(0), 0.5).max() <= 255


def test_hflip_moves_principal_point() -> None:
    s = _coded_sample(h=10, w=20)
    f = hflip(s)
    assert f.K[0, 2] == pytest.approx(20 - 1 - s.K[0, 2])
    np.testing.assert_array_equal(hflip(f).sparse, s.sparse)


def test_crop_larger_than_frame_is_an_error() -> None:
    with pytest.raises(DataError, match="smaller than the crop"):
        bottom_crop(_coded_sample(20, 30), 32, 64)
    s = _coded_sample(32, 64)
    assert EvalTransform(crop=(32, 64))(s, np.random.default_rng(0)) is s


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("aug")
    write_synthetic_kitti(out, frames=6, size=(64, 128), seed=0, eval_frames=0, workers=1)
    return out


def _epoch(ds: KittiDepthCompletion, epoch: int, workers: int) -> list[dict]:
    ds.set_epoch(epoch)
    loader = DataLoader(ds, batch_size=2, num_workers=workers, shuffle=False)
    return list(loader)


def test_same_samples_with_0_and_2_workers(tree: Path) -> None:
    ds = KittiDepthCompletion(tree, "train", transform=TrainTransform(crop=(64, 96), random_crop_height=48), seed=7)
    a, b = _epoch(ds, 3, 0), _epoch(ds, 3, 2)
    for x, y in zip(a, b, strict=True):
        for k in ("rgb", "semantic", "sparse", "gt", "K"):
            assert torch.equal(x[k], y[k]), k
    c = _epoch(ds, 4, 0)
    assert not all(torch.equal(x["rgb"], y["rgb"]) for x, y in zip(a, c, strict=True))  # new epoch, new draws
    assert torch.equal(_epoch(ds, 3, 0)[0]["rgb"], a[0]["rgb"])  # and back again
