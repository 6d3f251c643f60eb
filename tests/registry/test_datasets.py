"""Every registered dataset (:data:`semattnet.data.datasets.DATASETS`) on a tiny tree in its layout: the
frames of its evaluation split, the torch Dataset the evaluation reads, unknown splits and a corrupt file
refused in one line naming it, and its metrics (zero error for a prediction equal to the ground truth)."""

from __future__ import annotations

import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
import torch

from semattnet._errors import DataError, InputError
from semattnet.data.datasets import DATASETS, get_dataset
from semattnet.evaluation.protocols import protocol_metrics
from tests._base import RegistryTester
from tests.registry._trees import SIZE, corrupt, kitti_tree, nyu_tree, void_tree


@dataclass(frozen=True)
class DatasetFixture:
    """``make``: writes the tree under a folder and returns its root; ``frames``: how many its evaluation split
    holds; ``size``: their (H, W) as read; ``victim``: the frame path (``Frame.paths`` key) to corrupt."""

    make: Callable[[Path], Path]
    frames: int
    size: tuple[int, int]
    victim: str


@pytest.fixture(scope="module")
def trees(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Each dataset's tree, written once for the module."""
    root = tmp_path_factory.mktemp("datasets")
    return {name: fx.make(root / name) for name, fx in TestDatasets.fixtures.items() if name in DATASETS}


class TestDatasets(RegistryTester[DatasetFixture]):
    kind = "dataset"
    fixtures: ClassVar[Mapping[str, DatasetFixture]] = {
        "kitti-dc": DatasetFixture(kitti_tree, 1, SIZE, "sparse"),
        "nyuv2": DatasetFixture(nyu_tree, 2, (228, 304), "sparse"),
        "void": DatasetFixture(void_tree, 2, SIZE, "sparse"),
    }

    @classmethod
    def entries(cls) -> list[str]:
        return list(DATASETS)

    def test_smoke(self, entry: str, trees: dict[str, Path]) -> None:
        fx, spec = self.fixture(entry), get_dataset(entry)
        source = spec.source(trees[entry])
        frame = source.load(source.names[0])
        assert frame.rgb.shape == (*fx.size, 3) and frame.rgb.dtype == np.uint8
        assert frame.sparse.shape == fx.size and frame.sparse.dtype == np.float32
        assert frame.gt is not None and frame.gt.shape == fx.size
        assert spec.eval_split in spec.splits and spec.train_split in spec.splits

    def test_cardinality(self, entry: str, trees: dict[str, Path]) -> None:
        fx, spec = self.fixture(entry), get_dataset(entry)
        source = spec.source(trees[entry])
        assert len(source.names) == len(set(source.names)) == fx.frames
        ds = spec.dataset(trees[entry])
        assert len(ds) == fx.frames
        item = ds[0]
        h, w = item["rgb"].shape[-2:]
        assert item["rgb"].shape == (3, h, w) and item["sparse"].shape == item["gt"].shape == (1, h, w)
        assert (h, w) == fx.size or (h % 32, w % 32) == (0, 0)  # the protocol's size, or padded for the model

    def test_exception(self, entry: str, trees: dict[str, Path], tmp_path: Path) -> None:
        fx, spec = self.fixture(entry), get_dataset(entry)
        with pytest.raises(InputError, match=f"{entry} has no split 'nope'"):
            spec.source(trees[entry], "nope")
        root = tmp_path / entry
        shutil.copytree(trees[entry], root)
        source = spec.source(root)
        victim = corrupt(Path(source.load(source.names[0]).paths[fx.victim]))
        with pytest.raises(DataError) as err:
            spec.source(root).load(source.names[0])
        assert str(victim) in str(err.value) and "\n" not in str(err.value)

    def test_numerics(self, entry: str, trees: dict[str, Path]) -> None:
        """Loading is deterministic; the protocol's metrics of the ground truth itself are zero errors."""
        self.fixture(entry)
        spec = get_dataset(entry)
        name = spec.source(trees[entry]).names[0]
        a, b = spec.source(trees[entry]).load(name), spec.source(trees[entry]).load(name)
        assert np.array_equal(a.sparse, b.sparse) and np.array_equal(a.rgb, b.rgb)
        assert a.gt is not None
        gt = torch.from_numpy(a.gt)[None, None]
        metrics = protocol_metrics(spec.name)
        metrics.update(gt, gt)
        errors = {k: v for k, v in metrics.compute().items() if any(s in k for s in ("rmse", "mae", "abs_rel"))}
        assert errors and all(v == pytest.approx(0.0, abs=1e-6) for v in errors.values()), errors
