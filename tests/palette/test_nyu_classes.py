"""NYU Depth v2's 894 raw labels -> NYU-40 (the table of ankurhanda/nyuv2-meta-data, classMapping40.mat), and a
frame whose ``label`` key holds raw ids getting NYU-40 colours."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet.palette import NYU40_CLASSES, colors_to_ids, nyu894_to_nyu40
from semattnet.palette.nyu40_map import NYU894_TO_40, RAW_CLASSES, RAW_NAMES

# raw id, raw name (allClassName), NYU-40 class (className), read from classMapping40.mat at commit b92d15c
PUBLISHED = [
    (21, "wall", "wall"),
    (11, "floor", "floor"),
    (4, "ceiling", "ceiling"),
    (5, "chair", "chair"),
    (157, "bed", "bed"),
    (85, "books", "books"),
    (1, "book", "otherprop"),
    (172, "television", "television"),
    (331, "person", "person"),
    (12, "garbage bin", "otherfurniture"),
    (8, "dishwasher", "otherstructure"),
    (17, "refridgerator", "refrigerator"),
    (143, "floor mat", "floor mat"),
    (158, "night stand", "night stand"),
]
NAMES = [name for name, _ in NYU40_CLASSES]


@pytest.mark.parametrize(("raw", "raw_name", "nyu40"), PUBLISHED)
def test_a_handful_of_classes_match_the_published_table(raw: int, raw_name: str, nyu40: str) -> None:
    assert RAW_NAMES[raw - 1] == raw_name and NYU894_TO_40[raw] == NAMES.index(nyu40) + 1


def test_table_shape_and_the_lookup() -> None:
    assert len(NYU894_TO_40) == RAW_CLASSES + 1 == 895 and NYU894_TO_40[0] == 0 and len(RAW_NAMES) == 894
    assert all(1 <= v <= 40 for v in NYU894_TO_40[1:])
    assert nyu894_to_nyu40(np.array([[0, 21], [894, 11]])).tolist() == [[0, 1], [NYU894_TO_40[894], 2]]
    with pytest.raises(InputError, match=r"0\.\.894"):
        nyu894_to_nyu40(np.array([895]))


def test_a_frame_with_raw_labels_gets_nyu40_colours(tmp_path: Path) -> None:
    pytest.importorskip("h5py")
    from semattnet.data.datasets import get_dataset
    from tests.data._datasets import nyu_frame, write_h5

    arrays = nyu_frame(np.random.default_rng(0))
    label = np.full((480, 640), 21, np.uint16)  # raw "wall"
    label[:, 320:] = 157  # raw "bed"
    write_h5(tmp_path / "val" / "official" / "00001.h5", arrays | {"label": label})
    frame = get_dataset("nyuv2").source(tmp_path, "test").load("00001")
    ids = colors_to_ids(frame.semantic, palette="nyu40")
    assert set(np.unique(ids)) == {NAMES.index("wall") + 1, NAMES.index("bed") + 1}
