"""Indoor maps: a model's classes matched to NYU-40 by name (ADE20K's through NYU's raw names and the published
894 -> 40 table), ``hf:indoor``, ``semattnet segment --palette nyu40``, and ``--segment`` on ``--dataset nyuv2``
(train, evaluate, predict) with HDF5 files that hold no labels: the frames get the segmenter's maps, cached."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import read_image
from semattnet.palette import NYU40_CLASSES, colors_to_ids
from semattnet.segmentation import load_segmenter
from semattnet.segmentation.hf import HF_SEGMENTERS, hf_palette, resolve_hf_source
from semattnet.segmentation.indoor import nyu40_class, nyu40_indices
from tests.segmentation.test_hf import _save_tiny

transformers = pytest.importorskip("transformers")

NYU = {name: i + 1 for i, (name, _) in enumerate(NYU40_CLASSES)}
# a few ADE20K class names as the ADE20K checkpoints' id2label spell them (note "bed " with its space)
ADE = ["wall", "sky", "floor", "bed ", "windowpane", "painting", "chest of drawers", "stove", "television receiver"]


@pytest.mark.parametrize(
    ("label", "nyu40"),
    [
        ("wall", "wall"),
        ("bed ", "bed"),
        ("windowpane", "window"),
        ("painting", "picture"),
        ("chest of drawers", "dresser"),
        ("television receiver", "television"),
        ("Night_Stand", "night stand"),
        ("stove", "otherstructure"),
        ("bottle", "otherprop"),
        ("wardrobe", "otherfurniture"),
        ("refridgerator", "refrigerator"),
    ],
)
def test_class_names_map_to_nyu40(label: str, nyu40: str) -> None:
    assert nyu40_class(label) == NYU[nyu40]


def test_outdoor_classes_are_dropped() -> None:
    assert nyu40_class("sky") is None and nyu40_class("road") is None
    groups = nyu40_indices(dict(enumerate(ADE)))
    assert groups[NYU["window"] - 1] == [ADE.index("windowpane")] and all(1 not in g for g in groups)


def test_indoor_record_and_default_palettes() -> None:
    rec = HF_SEGMENTERS["indoor"]
    assert rec.palette == "nyu40" and rec.benchmark == "ADE20K val" and rec.cityscapes_val_miou is None
    assert resolve_hf_source("indoor") == ("nvidia/segformer-b5-finetuned-ade-640-640", None)
    assert hf_palette("indoor") == "nyu40" and hf_palette("default") == hf_palette("org/x") == "cityscapes"


@pytest.fixture(scope="module")
def ade_bed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny SegFormer with ADE20K names whose every pixel is "bed "."""
    return _save_tiny(tmp_path_factory.mktemp("hf") / "tiny-ade", ADE, winner=ADE.index("bed "))


def test_segmenter_in_nyu40(ade_bed: Path, tmp_path: Path) -> None:
    seg = load_segmenter(f"hf:{ade_bed}", "cpu", palette="nyu40")
    assert seg.palette == "nyu40" and (seg(np.zeros((1, 32, 48, 3), np.uint8)) == NYU["bed"]).all()
    images = tmp_path / "images"
    from semattnet.data.io import write_image

    write_image(images / "a.png", np.zeros((40, 72, 3), np.uint8))
    res = CliRunner().invoke(
        main,
        [
            "segment",
            "--model",
            f"hf:{ade_bed}",
            "--images",
            str(images),
            "--out",
            str(tmp_path / "sem"),
            "--palette",
            "nyu40",
            "--device",
            "cpu",
        ],
    )
    assert res.exit_code == 0, res.output
    assert (colors_to_ids(read_image(tmp_path / "sem" / "a.png"), palette="nyu40") == NYU["bed"]).all()


def _run(*args: object, code: int = 0) -> str:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == code, res.output + repr(res.exception)
    return res.output


def _nyu(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    pytest.importorskip("h5py")
    from tests.data._datasets import make_nyu

    monkeypatch.setenv("SEMATTNET_CACHE", str(tmp_path / "cache"))
    return make_nyu(tmp_path / "nyu", train=1, test=1)  # rgb and depth only, as the sparse-to-dense files


def test_segment_caches_the_split_maps(ade_bed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """predict --data --segment (a tiny Cityscapes model, the maps recoloured for it) segments the split once;
    the maps are the frames' (304x228, NYU-40) and a second run reuses them; options that cannot go together
    are refused."""
    import semattnet
    from semattnet.data.datasets import get_dataset
    from semattnet.training.config import TrainConfig
    from semattnet.weights.checkpoint import save_safetensors

    root, spec = _nyu(tmp_path, monkeypatch), f"hf:{ade_bed}"
    ckpt = tmp_path / "city.safetensors"
    save_safetensors(semattnet.build_model("semattnet_backbone", width=0.125).state_dict(), ckpt)
    args = [
        "predict",
        "--dataset",
        "nyuv2",
        "--data",
        root,
        "--checkpoint",
        ckpt,
        "--device",
        "cpu",
        "--segment",
        spec,
        "--palette-mismatch",
        "recolour",
    ]
    assert "1 segmented, 0 reused" in _run(*args, "--out", tmp_path / "p1")
    assert "0 segmented, 1 reused" in _run(*args, "--out", tmp_path / "p2")
    (cache,) = (tmp_path / "cache" / "semantic").glob("nyuv2-*")
    frame = get_dataset("nyuv2").source(root, "test", semantic_root=cache).load("00001")
    assert frame.semantic.shape == (228, 304, 3) and (colors_to_ids(frame.semantic, palette="nyu40") == 4).all()
    out = _run(
        "evaluate",
        "--dataset",
        "nyuv2",
        "--data",
        root,
        "--method",
        "classical",
        "--sparsity",
        "keep=1",
        "--segment",
        spec,
        "--out",
        tmp_path / "s",
        code=2,
    )
    assert "--segment is for the model's evaluation" in out
    with pytest.raises(ValueError, match="segment must be null when semantic_root is set"):
        TrainConfig(dataset="nyuv2", segment=spec, semantic_root=str(cache))


@pytest.mark.slow  # trains and scores at 256x320 on CPU (~40 s on a shared core)
def test_segment_on_nyu_hdf5_without_labels(ade_bed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """train, evaluate and predict --dataset nyuv2 --segment: every frame the model sees has the "bed" map."""
    import semattnet.data.datasets.frames as frames_module

    root = _nyu(tmp_path, monkeypatch)
    seen: list[set[int]] = []
    real = frames_module.frame_sample

    def spy(frame):  # type: ignore[no-untyped-def]
        seen.append(set(np.unique(colors_to_ids(frame.semantic, palette="nyu40")).tolist()))
        return real(frame)

    monkeypatch.setattr(frames_module, "frame_sample", spy)
    spec = f"hf:{ade_bed}"
    out = _run(
        "train",
        "--dataset",
        "nyuv2",
        "--data",
        root,
        "--segment",
        spec,
        "--out",
        tmp_path / "run",
        "--width",
        "0.125",
        "--batch-size",
        "1",
        "--workers",
        "0",
        "--max-steps",
        "1",
        "--set",
        "depth_head_init=[2,2]",
        "--set",
        "val_split=null",
        "--device",
        "cpu",
    )
    assert "1 segmented, 0 reused" in out and seen and all(s == {NYU["bed"]} for s in seen)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["segment"] == spec
    ckpt, seen[:] = tmp_path / "run" / "checkpoints" / "last.pt", []
    out = _run(
        "evaluate",
        "--dataset",
        "nyuv2",
        "--data",
        root,
        "--checkpoint",
        ckpt,
        "--segment",
        spec,
        "--workers",
        "0",
        "--device",
        "cpu",
    )
    assert "1 segmented, 0 reused" in out and seen and all(s == {NYU["bed"]} for s in seen)
    maps = list((tmp_path / "cache" / "semantic").glob("nyuv2-*/*.png"))
    assert len(maps) == 2 and all((colors_to_ids(read_image(m), palette="nyu40") == NYU["bed"]).all() for m in maps)
    out = _run(
        "predict",
        "--dataset",
        "nyuv2",
        "--data",
        root,
        "--checkpoint",
        ckpt,
        "--segment",
        spec,
        "--out",
        tmp_path / "pred",
        "--panel",
        "--device",
        "cpu",
    )
    assert "0 segmented, 1 reused" in out and "fallback" not in out
