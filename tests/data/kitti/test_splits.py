"""KITTI loaders on the real frame and on synthetic trees: pairing, geometry, refusals."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from semattnet.data.io import DataError, read_image, write_image
from semattnet.data.kitti.splits import KittiDepthCompletion
from semattnet.data.transforms import EvalTransform, TrainTransform
from semattnet.synthetic.tree import write_synthetic_kitti
from tests._helpers import SAMPLE

DRIVE = "2011_09_26_drive_0035_sync"


@pytest.fixture
def kitti(tmp_path: Path) -> Path:
    """The real frame plus a generated stand-in semantic map (Cityscapes colours by image row)."""
    root = tmp_path / "kitti"
    shutil.copytree(SAMPLE, root)
    for cam in ("02", "03"):
        rgb = read_image(root / f"kitti_raw/2011_09_26/{DRIVE}/image_{cam}/data/0000000005.png")
        sem = np.zeros_like(rgb)
        sem[: rgb.shape[0] // 2] = (70, 130, 180)  # sky
        sem[rgb.shape[0] // 2 :] = (128, 64, 128)  # road
        write_image(root / f"semantics/2011_09_26/{DRIVE}/image_{cam}/data/0000000005.png", sem)
    return root


def test_real_frame_pairing_and_units(kitti: Path) -> None:
    ds = KittiDepthCompletion(kitti, "train", transform=EvalTransform(crop=None))
    assert len(ds) == 2
    names = [f.name for f in ds.frames]
    assert names == [f"{DRIVE}_image_02_0000000005", f"{DRIVE}_image_03_0000000005"]
    for i, cam in enumerate(("02", "03")):
        assert ds.frames[i].rgb.parent.parent.name == f"image_{cam}" and ds.frames[i].gt.parent.name == f"image_{cam}"
        x = ds[i]
        assert x["rgb"].shape == (3, 375, 1242) and x["sparse"].shape == (1, 375, 1242)
        assert 0.03 < (x["sparse"] > 0).float().mean() < 0.05
        assert 0.13 < (x["gt"] > 0).float().mean() < 0.19
        assert 1.0 < x["gt"][x["gt"] > 0].min() and x["gt"].max() < 100  # metres
        assert x["K"][0, 0] == pytest.approx(721.5377)
        assert x["rgb"].max() > 200 and x["rgb"].dtype == torch.float32


def test_bottom_crop_geometry(kitti: Path) -> None:
    full = KittiDepthCompletion(kitti, "train", transform=EvalTransform(crop=None))[0]
    crop = KittiDepthCompletion(
        kitti, "train", transform=TrainTransform(random_crop_height=352, flip=False, jitter=0.0)
    )[0]
    top, left = 375 - 352, (1242 - 1216) // 2
    for key in ("rgb", "semantic", "sparse", "gt"):
        assert torch.equal(crop[key], full[key][:, top:, left : left + 1216]), key
    assert crop["K"][0, 2] == pytest.approx(full["K"][0, 2] - left)
    assert crop["K"][1, 2] == pytest.approx(full["K"][1, 2] - top)
    rnd = KittiDepthCompletion(kitti, "train", transform=TrainTransform())[0]
    assert rnd["rgb"].shape == (3, 320, 1216)


def test_missing_semantic_map_is_refused_by_name(kitti: Path) -> None:
    gone = kitti / f"semantics/2011_09_26/{DRIVE}/image_03/data/0000000005.png"
    gone.unlink()
    with pytest.raises(DataError, match=r"1 incomplete frame.*image_03/data/0000000005\.png"):
        KittiDepthCompletion(kitti, "train")
    with pytest.warns(UserWarning, match="skipped 1 incomplete"):
        ds = KittiDepthCompletion(kitti, "train", on_missing="skip")
    assert len(ds) == 1 and ds.skipped[0][1] == [gone]


def test_unpaired_ground_truth_is_reported(kitti: Path) -> None:
    velo = kitti / f"data_depth_velodyne/train/{DRIVE}/proj_depth/velodyne_raw/image_02/0000000005.png"
    velo.rename(velo.with_name("0000000006.png"))  # now frame 5 has gt only and frame 6 velodyne only
    with pytest.raises(DataError, match="2 incomplete") as info:
        KittiDepthCompletion(kitti, "train")
    assert "groundtruth/image_02/0000000006.png" in str(info.value)
    assert "velodyne_raw/image_02/0000000005.png" in str(info.value)


def test_size_mismatch_is_refused(kitti: Path) -> None:
    sem = kitti / f"semantics/2011_09_26/{DRIVE}/image_02/data/0000000005.png"
    write_image(sem, np.zeros((370, 1224, 3), np.uint8), overwrite=True)
    ds = KittiDepthCompletion(kitti, "train")
    with pytest.raises(DataError, match=r"image sizes disagree: .*1224x370"):
        ds[0]


@pytest.fixture(scope="module")
def synth_tree(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth")
    write_synthetic_kitti(out, frames=4, size=(96, 320), seed=3, eval_frames=2, workers=1)
    return out


@pytest.mark.parametrize(
    ("split", "n", "has_gt"), [("train", 4, True), ("val", 2, True), ("val_select", 2, True), ("test", 2, False)]
)
def test_synthetic_tree_reads_with_the_kitti_loader(synth_tree: Path, split: str, n: int, has_gt: bool) -> None:
    ds = KittiDepthCompletion(synth_tree, split, transform=EvalTransform(crop=None))
    assert len(ds) == n
    x = ds[0]
    assert ("gt" in x) == has_gt and x["sparse"].shape == (1, 96, 320)
    assert torch.isfinite(x["K"]).all()


@pytest.mark.parametrize(
    ("split", "victim", "action"),
    [
        (
            "train",
            "data_depth_annotated/train/2000_01_01_drive_0000_sync/proj_depth/groundtruth/image_02/0000000002.png",
            "remove",
        ),
        (
            "val_select",
            "data_depth_selection/val_selection_cropped/image/2000_01_01_drive_2000_sync_image_0000000001_image_02.png",
            "rename",
        ),
        ("test", "data_depth_selection/test_depth_completion_anonymous/semantic/0000000000.png", "remove"),
    ],
)
def test_synthetic_tree_with_a_file_gone_is_refused(synth_tree: Path, tmp_path: Path, split, victim, action) -> None:
    tree = tmp_path / "t"
    shutil.copytree(synth_tree, tree)
    path = tree / victim
    if action == "remove":
        path.unlink()
    else:
        path.rename(path.with_name("renamed.png"))
    with pytest.raises(DataError) as info:
        KittiDepthCompletion(tree, split)
    assert str(path) in str(info.value)


def test_empty_sparse_map_is_legal(synth_tree: Path, tmp_path: Path) -> None:
    from semattnet.data.io import write_depth

    tree = tmp_path / "t"
    shutil.copytree(synth_tree, tree)
    sparse = sorted((tree / "data_depth_selection/test_depth_completion_anonymous/velodyne_raw").glob("*.png"))[0]
    write_depth(sparse, np.zeros((96, 320)), overwrite=True)
    x = KittiDepthCompletion(tree, "test")[0]
    assert x["sparse"].max() == 0


def test_unknown_split_and_empty_root(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown split"):
        KittiDepthCompletion(tmp_path, "training")
    with pytest.raises(DataError, match="no val_select frames"):
        KittiDepthCompletion(tmp_path, "val_select")
