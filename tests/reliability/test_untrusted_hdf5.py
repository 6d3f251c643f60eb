"""A NYU v2 ``.h5`` file is read as an untrusted file: data kept outside it (external links, soft links,
virtual datasets, external raw storage) is refused, not fetched; sizes and dtypes are checked before a
byte is read; a group where a dataset belongs is refused by name. Each refusal is one DataError line that
starts with the file's path. The hostile files are built here with h5py."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import DataError
from semattnet.data.datasets import get_dataset
from semattnet.data.datasets.nyuv2 import read_nyu_h5
from tests.data._datasets import write_h5

h5py = pytest.importorskip("h5py")

H, W = 12, 16


def _rgb() -> np.ndarray:
    return np.full((3, H, W), 7, np.uint8)


def _depth(value: float = 2.0) -> np.ndarray:
    return np.full((H, W), value, np.float32)


def _outside(tmp_path: Path) -> Path:
    """A well-formed file outside the dataset root, which a link could borrow from."""
    return write_h5(tmp_path / "elsewhere" / "source.h5", {"rgb": _rgb(), "depth": _depth(1.5)})


def _external_link(f: Any, tmp_path: Path) -> None:
    f["rgb"] = h5py.ExternalLink(str(_outside(tmp_path)), "rgb")
    f["depth"] = h5py.ExternalLink(str(_outside(tmp_path)), "depth")


def _external_link_missing(f: Any, tmp_path: Path) -> None:
    f["rgb"] = h5py.ExternalLink(str(tmp_path / "no-such-file.h5"), "rgb")
    f["depth"] = _depth()


def _soft_link(f: Any, tmp_path: Path) -> None:
    f["stored"] = _rgb()
    f["rgb"] = h5py.SoftLink("/stored")
    f["depth"] = _depth()


def _virtual_missing_source(f: Any, tmp_path: Path) -> None:
    f["rgb"] = _rgb()
    layout = h5py.VirtualLayout((H, W), np.float32)
    layout[:] = h5py.VirtualSource(str(tmp_path / "gone.h5"), "depth", (H, W))
    f.create_virtual_dataset("depth", layout, fillvalue=3.0)  # HDF5 would answer 3.0 m everywhere


def _virtual_present_source(f: Any, tmp_path: Path) -> None:
    f["rgb"] = _rgb()
    layout = h5py.VirtualLayout((H, W), np.float32)
    layout[:] = h5py.VirtualSource(str(_outside(tmp_path)), "depth", (H, W))
    f.create_virtual_dataset("depth", layout)


def _external_storage_dev_zero(f: Any, tmp_path: Path) -> None:
    f.create_dataset("rgb", (3, H, W), np.uint8, external=[("/dev/zero", 0, h5py.h5f.UNLIMITED)])
    f["depth"] = _depth()


def _group_as_rgb(f: Any, tmp_path: Path) -> None:
    f.create_group("rgb")
    f["depth"] = _depth()


def _huge_declared(f: Any, tmp_path: Path) -> None:
    f.create_dataset("rgb", (3, 60000, 60000), np.uint8, chunks=(1, 64, 64))  # a few KB on disk, 10 GB declared
    f.create_dataset("depth", (60000, 60000), np.float32, chunks=(64, 64))


def _record_dtype(f: Any, tmp_path: Path) -> None:
    f["rgb"] = np.zeros((3, H, W), [("a", np.uint8), ("b", np.uint8)])
    f["depth"] = _depth()


def _empty_image(f: Any, tmp_path: Path) -> None:
    f["rgb"] = np.zeros((3, 0, 0), np.uint8)
    f["depth"] = np.zeros((0, 0), np.float32)


HOSTILE: dict[str, tuple[Callable[[Any, Path], None], str]] = {
    "external link": (_external_link, "'rgb' is an external link to .*source.h5"),
    "external link to a missing file": (_external_link_missing, "'rgb' is an external link to .*no-such-file.h5"),
    "soft link": (_soft_link, "'rgb' is a soft link to /stored"),
    "virtual dataset, source missing": (_virtual_missing_source, "'depth' is a virtual dataset"),
    "virtual dataset, source present": (_virtual_present_source, "'depth' is a virtual dataset"),
    "external raw storage on /dev/zero": (_external_storage_dev_zero, "'rgb' keeps its data in external .*/dev/zero"),
    "group for rgb": (_group_as_rgb, "'rgb' is an HDF5 group, not a dataset"),
    "3x60000x60000 declared": (_huge_declared, "60000x60000 is above the limit"),
    "records for rgb": (_record_dtype, "'rgb' must be uint8"),
    "0x0 image": (_empty_image, "'rgb' \\(3, H, W\\) must be two positive integers"),
}


def _hostile(tmp_path: Path, build: Callable[[Any, Path], None]) -> Path:
    path = tmp_path / "root" / "val" / "official" / "00001.h5"
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        build(f, tmp_path)
    return path


@pytest.fixture
def no_reads(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any read of a dataset's data fails the test: the refusals come from metadata alone."""

    def refuse(self: Any, *args: Any, **kwargs: Any) -> None:
        raise AssertionError(f"dataset {self.name} was read before it was checked")

    monkeypatch.setattr(h5py.Dataset, "__getitem__", refuse)
    monkeypatch.setattr(h5py.Dataset, "read_direct", refuse)


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_file_is_one_line_naming_it(tmp_path: Path, case: str, no_reads: None) -> None:
    build, message = HOSTILE[case]
    path = _hostile(tmp_path, build)
    with pytest.raises(DataError, match=message) as exc:
        read_nyu_h5(path)
    assert str(exc.value).startswith(f"{path}: ") and "\n" not in str(exc.value)


def test_the_source_and_data_check_name_each_hostile_file(tmp_path: Path, no_reads: None) -> None:
    folder = tmp_path / "root" / "val" / "official"
    for i, (build, _) in enumerate(HOSTILE.values()):
        one = _hostile(tmp_path / f"case{i}", build)
        folder.mkdir(parents=True, exist_ok=True)
        one.rename(folder / f"{i:05d}.h5")
    src = get_dataset("nyuv2").source(tmp_path / "root", "test")
    for name in src.names:
        with pytest.raises(DataError) as exc:
            src.load(name)
        assert str(exc.value).startswith(str(folder / f"{name}.h5"))
    from semattnet.cli import main

    result = CliRunner().invoke(main, ["data", "check", "--dataset", "nyuv2", str(tmp_path / "root")])
    assert result.exit_code == 1 and "Traceback" not in result.output, result.output
    for i in range(len(HOSTILE)):
        assert f"{i:05d}.h5: " in result.output


def test_plain_files_still_read(tmp_path: Path) -> None:
    path = tmp_path / "plain.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("rgb", data=_rgb(), chunks=(3, 4, 4), compression="gzip")  # chunked, compressed
        f.create_dataset("depth", data=_depth())  # contiguous
        f.create_dataset("label", data=np.ones((H, W), np.uint8))
    rgb, depth, label = read_nyu_h5(path)
    assert rgb.shape == (H, W, 3) and float(depth.mean()) == 2.0 and label is not None and label.max() == 1


def test_a_dataset_over_the_byte_bound_is_not_read(tmp_path: Path, no_reads: None) -> None:
    from semattnet.data.datasets.hdf5 import MAX_DATASET_BYTES, plain_dataset, read_bounded

    path = tmp_path / "big.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("label", (MAX_DATASET_BYTES // 8 + 1,), np.int64, chunks=(1024,))
    with h5py.File(path, "r") as f:
        ds = plain_dataset(f, "label", path)
        with pytest.raises(DataError, match=f"{path}: 'label' declares .* above the limit"):
            read_bounded(ds, "label", path)
        assert plain_dataset(f, "absent", path) is None


def test_a_fifo_in_place_of_a_file_is_refused(tmp_path: Path) -> None:
    import os

    fifo = tmp_path / "00001.h5"
    os.mkfifo(fifo)
    with pytest.raises(DataError, match=f"{fifo}: is a FIFO"):
        read_nyu_h5(fifo)
