"""Every registered frame source (:data:`semattnet.data.sources.registry.SOURCES`, the robot ones included) on
tiny inputs: names, frames and their shapes, what it reads, a corrupt input refused in one line naming the
file, deterministic loads and, where a reference exists, the values against it."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from semattnet._errors import DataError
from semattnet.data.frames import Frame, IndexedSource
from semattnet.data.sources.registry import SOURCES, list_sources
from tests._base import RegistryTester
from tests._helpers import agreement
from tests.inference._raw_sample import official_velodyne_raw, three_frame_drive
from tests.registry._trees import SIZE, corrupt, folder_frames, kitti_tree, nyu_tree, sensor_bag, void_tree


def _same_as_gt(frame: Frame) -> None:
    assert frame.gt is not None and np.count_nonzero(frame.sparse) > 0
    np.testing.assert_array_equal(frame.sparse[frame.sparse > 0], frame.gt[frame.sparse > 0])


def _official_scan(frame: Frame) -> None:
    """The bundled frame's projected scan agrees with KITTI's own velodyne_raw map."""
    from semattnet.data.io import read_depth

    assert agreement(frame.sparse, read_depth(official_velodyne_raw("02")), radius=1) > 0.9


def _folder_values(frame: Frame) -> None:
    expected = np.zeros(SIZE, np.float32)
    expected[::4, ::4] = 10.0
    np.testing.assert_array_equal(frame.sparse, expected)


def _open_bag(root: Path) -> IndexedSource:
    from semattnet.robotics import BagSource
    from semattnet.robotics.bags import BagTopics

    topics = BagTopics()
    return BagSource(root / "drive.bag", topics.image, topics.points)


def _open_raw(root: Path) -> IndexedSource:
    from semattnet.data.sources import RawDriveSource

    return RawDriveSource(next(root.glob("*/*_sync")))


@dataclass(frozen=True)
class SourceFixture:
    """``write`` the inputs under a folder, ``open`` the source on them; ``frames``: how many it lists,
    ``size``: their (H, W); ``victim``: the input (``Frame.paths`` key) to corrupt; ``check``: the values of
    its first frame against a reference, where one exists."""

    write: Callable[[Path], object]
    open: Callable[[Path], IndexedSource]
    frames: int
    size: tuple[int, int]
    victim: str
    check: Callable[[Frame], None] | None = None
    needs: str | None = None


def _folder(root: Path) -> IndexedSource:
    from semattnet.data.sources import FolderSource

    return FolderSource.pair(root / "rgb", root / "sparse")


def _dataset(name: str) -> Callable[[Path], IndexedSource]:
    from semattnet.data.datasets import get_dataset

    return lambda root: get_dataset(name).source(root)


KITTI_RAW = (375, 1242)
FIXTURES = {
    "folder": SourceFixture(folder_frames, _folder, 2, SIZE, "sparse", _folder_values),
    "kitti-dc": SourceFixture(kitti_tree, _dataset("kitti-dc"), 1, SIZE, "sparse"),
    "kitti-raw": SourceFixture(three_frame_drive, _open_raw, 3, KITTI_RAW, "scan", _official_scan),
    "nyuv2": SourceFixture(nyu_tree, _dataset("nyuv2"), 2, (228, 304), "sparse", _same_as_gt),
    "void": SourceFixture(void_tree, _dataset("void"), 2, SIZE, "sparse", _same_as_gt),
    "bag": SourceFixture(sensor_bag, _open_bag, 2, KITTI_RAW, "bag", _official_scan, needs="rosbags"),
}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The inputs of each source, written once for the module (on first use)."""
    root = tmp_path_factory.mktemp("sources")

    class Written(dict[str, Path]):
        def __missing__(self, name: str) -> Path:
            fx = FIXTURES[name]
            if fx.needs is not None:
                pytest.importorskip(fx.needs)
            folder = root / name
            folder.mkdir()
            fx.write(folder)
            self[name] = folder
            return folder

    return Written()


class TestSources(RegistryTester[SourceFixture]):
    kind = "source"
    fixtures: ClassVar[Mapping[str, SourceFixture]] = FIXTURES

    @classmethod
    def entries(cls) -> list[str]:
        return list_sources()

    def test_smoke(self, entry: str, inputs: dict[str, Path]) -> None:
        fx = self.fixture(entry)
        source = fx.open(inputs[entry])
        assert isinstance(source, SOURCES[entry].cls)
        frame = source.load(source.names[0])
        assert isinstance(frame, Frame) and frame.name == source.names[0]
        assert frame.rgb.shape == (*fx.size, 3) and frame.rgb.dtype == np.uint8
        assert frame.sparse.shape == fx.size and frame.sparse.dtype == np.float32

    def test_cardinality(self, entry: str, inputs: dict[str, Path]) -> None:
        fx = self.fixture(entry)
        source = fx.open(inputs[entry])
        assert len(source.names) == len(set(source.names)) == fx.frames
        assert source.inputs() and all(Path(p).exists() for p in source.inputs())
        source.check()  # every frame decodes
        assert all(source.load(n).size == fx.size for n in source.names[1:])

    def test_exception(self, entry: str, inputs: dict[str, Path], tmp_path: Path) -> None:
        """A corrupt input: one line naming the file, when the source is opened or the frame loaded."""
        fx = self.fixture(entry)
        root = tmp_path / entry
        shutil.copytree(inputs[entry], root)
        source = fx.open(root)
        name = source.names[0]
        victim = corrupt(Path(source.load(name).paths[fx.victim]))
        with pytest.raises(DataError) as err:
            fx.open(root).load(name)
        assert str(victim) in str(err.value) and "\n" not in str(err.value)

    def test_numerics(self, entry: str, inputs: dict[str, Path]) -> None:
        """Loads are deterministic, depths are metres (0 = none) and, where a reference exists, match it."""
        fx = self.fixture(entry)
        source = fx.open(inputs[entry])
        a, b = source.load(source.names[0]), fx.open(inputs[entry]).load(source.names[0])
        assert np.array_equal(a.sparse, b.sparse) and np.array_equal(a.rgb, b.rgb)
        assert np.isfinite(a.sparse).all() and 0 <= a.sparse.min() and a.sparse.max() < 256
        if fx.check is not None:
            fx.check(a)


def test_each_dataset_is_the_source_of_its_name(inputs: dict[str, Path]) -> None:
    """A dataset and its frames' source go by one name (``kitti-dc``, ``nyuv2``, ``void``)."""
    from semattnet.data.datasets import DATASETS

    for name in DATASETS:
        assert isinstance(FIXTURES[name].open(inputs[name]), SOURCES[name].cls), name
