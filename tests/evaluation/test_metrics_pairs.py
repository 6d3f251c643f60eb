"""``semattnet metrics``: one pair of files as well as two folders, and KITTI selection names paired as the
split's own layout has them (``predict --rgb image/`` names outputs like the images)."""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import write_depth, write_image
from semattnet.data.kitti.layout import selection_key, selection_name

DRIVE = "2011_09_26_drive_0002_sync"
FRAMES = ("0000000005", "0000000020")


def _selection(root: Path) -> Path:
    """A tiny ``val_selection_cropped``: image/, velodyne_raw/, groundtruth_depth/ (two 24x40 frames)."""
    rng = np.random.default_rng(0)
    for d in ("image", "velodyne_raw", "groundtruth_depth"):
        (root / d).mkdir(parents=True)
    for frame in FRAMES:
        gt = rng.uniform(2, 30, (24, 40)).astype(np.float32)
        name = partial(selection_name, DRIVE, frame=frame, camera="02")
        write_image(root / "image" / name("image"), rng.integers(0, 256, (24, 40, 3), dtype=np.uint8))
        write_depth(root / "velodyne_raw" / name("velodyne_raw"), np.where(rng.random((24, 40)) < 0.2, gt, 0))
        write_depth(root / "groundtruth_depth" / name("groundtruth_depth"), gt)
    return root


def _named_like(sel: Path, kind: str, out: Path) -> Path:
    """The ground truth copied into ``out``, named like the selection's ``kind`` files (a perfect prediction)."""
    out.mkdir()
    for gt in (sel / "groundtruth_depth").glob("*.png"):
        (out / gt.name.replace("_groundtruth_depth_", f"_{kind}_", 1)).write_bytes(gt.read_bytes())
    return out


def _metrics(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(main, ["metrics", *(str(a) for a in args)])
    return res.exit_code, res.output


def test_selection_keys() -> None:
    gt = selection_name(DRIVE, "groundtruth_depth", FRAMES[0], "02")
    for kind in ("image", "velodyne_raw", "groundtruth_depth"):
        assert selection_key(selection_name(DRIVE, kind, FRAMES[0], "02")) == gt
    assert selection_key("0000000005.png") == "0000000005.png"  # any other name as it is


def test_predict_on_a_selection_then_metrics(tmp_path: Path) -> None:
    sel = _selection(tmp_path / "val_selection_cropped")
    res = CliRunner().invoke(
        main,
        [
            "predict",
            "--method",
            "classical",
            "--rgb",
            str(sel / "image"),
            "--sparse",
            str(sel / "velodyne_raw"),
            "--out",
            str(tmp_path / "pred"),
        ],
    )
    assert res.exit_code == 0, res.output
    code, output = _metrics(tmp_path / "pred", sel / "groundtruth_depth", "--json", tmp_path / "m.json")
    assert code == 0, output
    assert json.loads((tmp_path / "m.json").read_text())["images"] == len(FRAMES)


def test_one_pair_of_files_scores_as_a_folder_of_one(tmp_path: Path) -> None:
    sel = _selection(tmp_path / "sel")
    pred, gt = (sorted((sel / d).glob("*.png"))[0] for d in ("velodyne_raw", "groundtruth_depth"))
    code, output = _metrics(pred, gt, "--json", tmp_path / "one.json")
    assert code == 0, output
    (tmp_path / "p").mkdir()
    (tmp_path / "g").mkdir()
    (tmp_path / "p" / pred.name).write_bytes(pred.read_bytes())
    (tmp_path / "g" / gt.name).write_bytes(gt.read_bytes())
    assert _metrics(tmp_path / "p", tmp_path / "g", "--json", tmp_path / "folder.json")[0] == 0
    one, folder = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("one", "folder"))
    assert one == folder and one["images"] == 1


def test_a_file_and_a_folder_or_two_names_of_one_frame_are_refused(tmp_path: Path) -> None:
    sel = _selection(tmp_path / "sel")
    gt_dir = sel / "groundtruth_depth"
    code, output = _metrics(sorted(gt_dir.glob("*.png"))[0], gt_dir)
    assert code == 1 and "PRED and GT must be two PNG files or two folders" in output
    both = _named_like(sel, "image", tmp_path / "both")
    scan = sorted((sel / "velodyne_raw").glob("*.png"))[0]
    (both / scan.name).write_bytes(scan.read_bytes())  # one frame named like its image and like its scan: which?
    code, output = _metrics(both, gt_dir)
    assert code == 1 and "are predictions of one KITTI frame" in output and scan.name in output, output
    assert len([x for x in output.splitlines() if x.strip()]) == 1


@pytest.mark.parametrize("kind", ["image", "velodyne_raw"])
def test_metrics_pairs_selection_names(tmp_path: Path, kind: str) -> None:
    sel = _selection(tmp_path / "sel")
    pred = _named_like(sel, kind, tmp_path / "pred")
    code, output = _metrics(pred, sel / "groundtruth_depth", "--json", tmp_path / "m.json")
    assert code == 0, output
    m = json.loads((tmp_path / "m.json").read_text())
    assert m["images"] == len(FRAMES) and m["rmse_mm"] == 0.0
