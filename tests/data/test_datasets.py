"""The dataset registry and its readers: NYU v2 HDF5 and VOID list files, errors naming the file, the seeded
500-sample draw, the NYU-40 palette, ``data download --dataset`` through a local ``file://`` mirror."""

from __future__ import annotations

import os
import tarfile
from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import DataError, InputError
from semattnet.data.datasets import DATASETS, get_dataset
from tests.data._datasets import make_nyu, make_void, nyu_frame, write_h5

pytest.importorskip("h5py")


def test_registry_entries_and_unknown_name() -> None:
    assert list(DATASETS) == ["kitti-dc", "nyuv2", "void"] and get_dataset(None).name == "kitti-dc"
    nyu, void = get_dataset("nyuv2"), get_dataset("void")
    assert (nyu.crop, nyu.depth_range, nyu.sparse_samples, nyu.palette) == ((228, 304), (0.1, 10.0), 500, "nyu40")
    assert void.depth_range == (0.2, 5.0) and void.units == "mm"
    with pytest.raises(InputError, match="unknown dataset .nyu.; available: kitti-dc, nyuv2, void"):
        get_dataset("nyu")
    with pytest.raises(InputError, match="nyuv2 has no split 'val_select'"):
        nyu.source("x", "val_select")


def test_nyu_frame_protocol(tmp_path: Path) -> None:
    root = make_nyu(tmp_path, train=1, test=3, label=True)
    src = get_dataset("nyuv2").source(root, "test")
    a, b = src.load("00001"), src.load("00002")
    assert a.rgb.shape == (228, 304, 3) and a.gt.shape == (228, 304) and a.rgb.dtype == np.uint8
    assert np.count_nonzero(a.sparse) == 500 and np.all(a.sparse[a.sparse > 0] == a.gt[a.sparse > 0])
    # reproducible (a second source, a second load) and different per frame
    again = get_dataset("nyuv2").source(root, "test").load("00001")
    assert np.array_equal(a.sparse, again.sparse)
    assert not np.array_equal(a.sparse > 0, b.sparse > 0)
    # the K of the resized (x0.5) and centre-cropped (8 columns, 6 rows) frame
    assert a.K[0, 2] == pytest.approx(325.58244941119034 / 2 - 8) and a.K[1, 2] == pytest.approx(253.73616633 / 2 - 6)
    # labels -> NYU-40 colours (ids 1..4 in column bands)
    from semattnet.palette import colors_to_ids

    assert set(np.unique(colors_to_ids(a.semantic, palette="nyu40"))) == {1, 2, 3, 4}
    assert src.load("00001").semantic is not None and src.palette == "nyu40"


def test_train_draw_changes_with_epoch(tmp_path: Path) -> None:
    ds = get_dataset("nyuv2").dataset(make_nyu(tmp_path, train=1, test=1), train=True)
    first = ds[0]["sparse"]
    ds.set_epoch(1)
    assert ds[0]["sparse"].shape == (1, 256, 320) and not bool((first > 0).eq(ds[0]["sparse"] > 0).all())
    assert int((first > 0).sum()) == 500 and float(ds[0]["gt"][0, :28].abs().sum()) == 0.0  # top padding: no gt


@pytest.mark.parametrize(
    ("arrays", "message"),
    [
        ({"image": np.zeros((3, 8, 8), np.uint8), "depth": np.ones((8, 8), np.float32)}, "missing HDF5 key"),
        ({"rgb": np.zeros((3, 8, 8), np.float32), "depth": np.ones((8, 8), np.float32)}, "'rgb' must be uint8"),
        ({"rgb": np.zeros((3, 8, 8), np.uint8), "depth": np.ones((8, 8), np.uint16)}, "'depth' must be float32"),
        ({"rgb": np.zeros((3, 8, 8), np.uint8), "depth": np.full((8, 8), 2500.0, np.float32)}, "millimetres"),
        (
            {"rgb": np.zeros((3, 1, 1), np.uint8), "depth": np.ones((1, 1), np.float32)},
            r"'rgb' is 1x1; the NYU v2 protocol \(NYU_K, the resize to 320x240\) is for 640x480",
        ),  # not upsampled
    ],
)
def test_nyu_bad_files_are_one_line(tmp_path: Path, arrays: dict, message: str) -> None:
    bad = write_h5(tmp_path / "val" / "official" / "00001.h5", arrays)
    src = get_dataset("nyuv2").source(tmp_path, "test")
    with pytest.raises(DataError, match=message) as exc:
        src.load("00001")
    assert str(exc.value).startswith(str(bad)) and "\n" not in str(exc.value)


def test_nyu_missing_split_and_not_hdf5(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="val/official: split folder not found"):
        get_dataset("nyuv2").source(tmp_path, "test")
    (tmp_path / "val" / "official").mkdir(parents=True)
    (tmp_path / "val" / "official" / "00001.h5").write_bytes(b"not hdf5")
    with pytest.raises(DataError, match="00001.h5: not a readable HDF5 file"):
        get_dataset("nyuv2").source(tmp_path, "test").load("00001")


def test_void_frames_and_intrinsics_formats(tmp_path: Path) -> None:
    for fmt in ("txt", "npy"):
        root = make_void(tmp_path / fmt, train=1, test=2, h=32, w=64, k_format=fmt)
        src = get_dataset("void").source(root, "test")  # the release folder: void_1500 inside
        f = src.load(src.names[0])
        assert f.rgb.shape == (32, 64, 3) and f.K[0, 0] == 500.0 and f.gt.max() <= 4.5
        assert np.all(f.sparse[f.sparse > 0] == f.gt[f.sparse > 0])  # 1/256 m PNGs, validity applied


def test_void_errors_name_the_file(tmp_path: Path) -> None:
    root = make_void(tmp_path, train=1, test=2, h=32, w=64) / "void_1500"
    (root / "test_ground_truth.txt").unlink()
    with pytest.raises(DataError, match=r"test_ground_truth.txt: split file not found"):
        get_dataset("void").source(root, "test")
    (root / "train_image.txt").write_text((root / "train_image.txt").read_text() * 2)
    with pytest.raises(DataError, match="lists differ in length"):
        get_dataset("void").source(root, "train")
    mm = tmp_path / "mm"
    make_void(mm, train=0, test=1, h=32, w=64)
    gt = next((mm / "void_1500" / "data").glob("*/ground_truth/*.png"))
    from PIL import Image

    Image.fromarray(np.full((32, 64), 60000, np.uint16)).save(gt)  # 234 m: millimetres stored as 1/256 m
    src = get_dataset("void").source(mm / "void_1500", "test")
    with pytest.raises(DataError, match="millimetres") as exc:
        src.load(src.names[0])
    assert str(exc.value).startswith(str(gt))


def test_void_list_with_a_byte_order_mark_keeps_its_first_entry(tmp_path: Path) -> None:
    root = make_void(tmp_path, train=0, test=2, h=32, w=64) / "void_1500"
    for list_file in root.glob("test_*.txt"):  # as Windows Notepad saves UTF-8
        list_file.write_bytes(b"\xef\xbb\xbf" + list_file.read_bytes())
    src = get_dataset("void").source(root, "test")
    assert len(src.names) == 2 and src.load(src.names[0]).rgb.shape == (32, 64, 3)


@pytest.mark.parametrize("entry", ["validity_map", "intrinsics", "the list of ground truth"])
def test_void_entry_that_is_a_fifo_says_so(tmp_path: Path, entry: str) -> None:
    root = make_void(tmp_path, train=0, test=1, h=32, w=64) / "void_1500"
    if entry.startswith("the list"):
        target = root / "test_ground_truth.txt"
    else:
        target = root.parent / (root / f"test_{entry}.txt").read_text().split()[0]
    target.unlink()
    os.mkfifo(target)
    with pytest.raises(DataError) as exc:
        src = get_dataset("void").source(root, "test")
        src.load(src.names[0])
    assert str(exc.value).startswith(f"{target}: is a FIFO, not a regular")


@pytest.mark.parametrize("k", ["nan 0 16\n0 500 16\n0 0 1\n", "0 0 16\n0 500 16\n0 0 1\n"])
def test_void_meaningless_intrinsics_name_the_file(tmp_path: Path, k: str) -> None:
    root = make_void(tmp_path, train=0, test=1, h=32, w=64) / "void_1500"
    k_txt = next((root / "data").glob("*/K.txt"))
    k_txt.write_text(k)
    src = get_dataset("void").source(root, "test")
    with pytest.raises(DataError) as exc:
        src.load(src.names[0])
    assert str(exc.value).startswith(f"{k_txt}: K") and "\n" not in str(exc.value)


def test_data_check_reports_bad_frames(tmp_path: Path) -> None:
    root = make_nyu(tmp_path, train=0, test=2)
    write_h5(root / "val" / "official" / "00002.h5", {"rgb": nyu_frame(np.random.default_rng(0))["rgb"]})
    lines: list[str] = []
    assert get_dataset("nyuv2").check([root], log=lines.append) == 1
    assert any("00002.h5: missing HDF5 key(s) ['depth']" in line for line in lines)
    assert get_dataset("void").check([tmp_path / "nothing"], log=lines.append) == 1


def test_palettes_one_home_and_mismatch() -> None:
    import semattnet
    from semattnet.palette import (
        PALETTES,
        PaletteMismatchError,
        UnknownColorError,
        check_palette,
        colors_to_ids,
        ids_to_colors,
    )

    assert semattnet.palette.PALETTES is PALETTES and set(PALETTES) == {"cityscapes", "nyu40"}
    assert PALETTES["nyu40"].num_classes == 40 and len({c for _, c in PALETTES["nyu40"].classes}) == 40
    nyu = ids_to_colors(np.array([[1, 2], [40, 0]]), palette="nyu40")
    assert tuple(nyu[0, 0]) == (174, 199, 232) and tuple(nyu[1, 1]) == (0, 0, 0)  # wall; 0 = unlabelled
    assert colors_to_ids(nyu, palette="nyu40").tolist() == [[1, 2], [40, 255]]
    with pytest.raises(PaletteMismatchError, match="NYU-40 palette, but the Cityscapes palette was expected"):
        colors_to_ids(nyu, source="m.png")
    with pytest.raises(UnknownColorError, match="outside the NYU-40 palette"):
        colors_to_ids(np.full((2, 2, 3), 7, np.uint8), palette="nyu40")
    with pytest.raises(PaletteMismatchError, match="trained with the NYU-40 palette"):
        check_palette("nyu40", "cityscapes")
    assert semattnet.models.SemAttNetConfig().palette == "cityscapes"
    with pytest.raises(ValueError, match="palette must be one of"):
        semattnet.models.SemAttNetConfig(palette="ade20k")


def test_download_nyu_through_a_file_mirror(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from semattnet.cache import read_pins
    from semattnet.data.download import download_dataset
    from tests._helpers import online_cache

    cache = online_cache(monkeypatch, tmp_path / "cache")
    tree = make_nyu(tmp_path / "src" / "nyudepthv2", train=1, test=1)
    mirror = tmp_path / "mirror"
    mirror.mkdir()
    with tarfile.open(mirror / "nyudepthv2.tar.gz", "w:gz") as tf:
        tf.add(tree, arcname="nyudepthv2")
    out, lines = tmp_path / "nyu", []
    with pytest.raises(ValueError, match="--accept-license"):
        download_dataset("nyuv2", out, mirror=mirror.as_uri())
    kw = {"accept_license": True, "mirror": mirror.as_uri(), "progress": False, "log": lines.append}
    assert download_dataset("nyuv2", out, **kw) == 0
    assert (out / "val" / "official" / "00001.h5").is_file() and (out / "train" / "scene_00" / "00001.h5").is_file()
    assert any("nyudepthv2.tar.gz" in k for k in read_pins(cache)) and any("Silberman" in line for line in lines)
    assert download_dataset("nyuv2", out, **kw) == 0 and any("2 already there" in line for line in lines)


def test_tar_members_leaving_the_folder_are_refused(tmp_path: Path) -> None:
    import io

    from semattnet.data.archives import UnsafeArchiveError, extract_tar

    path = tmp_path / "evil.tar"
    with tarfile.open(path, "w") as tf:
        info = tarfile.TarInfo("../outside.txt")
        info.size = 2
        tf.addfile(info, io.BytesIO(b"hi"))
    with pytest.raises(UnsafeArchiveError, match="outside.txt"):
        extract_tar(path, tmp_path / "dest")
    assert not (tmp_path / "outside.txt").exists()


def test_the_cropped_splits_are_the_entrys_not_its_names() -> None:
    """Which splits the protocol crops is a field of the entry: any dataset may declare them."""
    from dataclasses import replace

    from semattnet.data.datasets import get_dataset

    spec = replace(get_dataset("nyuv2"), name="indoor-cropped", crop=(8, 12), crop_splits=("test",))
    assert spec.eval_crop("test", (16, 24)) == (8, 12)
    assert spec.eval_crop("train", (16, 24)) is None and spec.eval_crop("test", (8, 12)) is None
    assert get_dataset("kitti-dc").eval_crop("val", (375, 1242)) == (352, 1216)
    assert get_dataset("kitti-dc").eval_crop("val_select", (375, 1242)) is None


def test_a_scored_run_names_every_bad_file_in_one_line(tmp_path: Path) -> None:
    """evaluate stops before completing anything when a frame is bad; its one line names each bad file, not
    only the first, so that one run says what to repair."""
    from click.testing import CliRunner

    from semattnet.cli import main
    from tests.data._datasets import make_nyu

    root = make_nyu(tmp_path / "nyu", train=0, test=4)
    bad_dtype = write_h5(
        root / "val" / "official" / "00002.h5",
        {"rgb": np.zeros((3, 8, 8), np.float32), "depth": np.ones((8, 8), np.float32)},
    )
    not_hdf5 = root / "val" / "official" / "00004.h5"
    not_hdf5.write_bytes(b"not hdf5")
    ckpt = tmp_path / "never-loaded.safetensors"  # every check comes before the weights are read
    ckpt.write_bytes(b"")
    args = ["evaluate", "--dataset", "nyuv2", "--data", str(root), "--checkpoint", str(ckpt), "--workers", "0"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1, res.output
    line = res.output.strip()
    assert line.startswith("Error: 2 of 4 frames cannot be read: ") and "\n" not in line
    assert f"{bad_dtype}: 'rgb' must be uint8" in line and f"{not_hdf5}: not a readable HDF5 file" in line
