"""``hf:`` segmenters: a tiny random SegFormer saved with save_pretrained, loaded from a local folder."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.data.io import read_image, write_image
from semattnet.palette import PALETTE, TRAIN_CLASSES
from semattnet.segmentation import load_segmenter
from semattnet.segmentation.hf import HF_SEGMENTERS, cityscapes_indices, resolve_hf_source

transformers = pytest.importorskip("transformers")

NAMES = [name for name, _ in TRAIN_CLASSES]
# the same 19 classes as some checkpoints spell them, in another order, plus one non-Cityscapes class
VARIANTS = [
    "car",
    "Road",
    "side_walk",
    "Building",
    "wall",
    "fence",
    "pole",
    "Traffic-Light",
    "traffic_sign",
    "vegetation",
    "terrain",
    "sky",
    "pedestrian",
    "rider",
    "unlabeled",
    "truck",
    "bus",
    "on rails",
    "motorbike",
    "bicycles",
]


def _save_tiny(folder: Path, labels: list[str], winner: int | None = None) -> Path:
    torch.manual_seed(0)
    config = transformers.SegformerConfig(
        num_encoder_blocks=4,
        depths=[1, 1, 1, 1],
        hidden_sizes=[8, 16, 32, 64],
        num_attention_heads=[1, 1, 1, 1],
        sr_ratios=[8, 4, 2, 1],
        decoder_hidden_size=16,
        num_labels=len(labels),
        id2label=dict(enumerate(labels)),
        label2id={n: i for i, n in enumerate(labels)},
    )
    model = transformers.SegformerForSemanticSegmentation(config).eval()
    if winner is not None:  # every pixel -> class `winner`
        with torch.no_grad():
            model.decode_head.classifier.weight.zero_()
            model.decode_head.classifier.bias.zero_()
            model.decode_head.classifier.bias[winner] = 10.0
    model.save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _save_tiny(tmp_path_factory.mktemp("hf") / "tiny-segformer", NAMES)


def _palette_only(colours: np.ndarray) -> bool:
    flat = colours.reshape(-1, 3)
    return bool((flat[:, None, :] == PALETTE[None]).all(-1).any(-1).all())


def test_segments_images_with_palette_colours_and_sizes(tiny: Path, tmp_path: Path) -> None:
    images = tmp_path / "raw/2011_09_26/d/image_02/data"
    rng = np.random.default_rng(0)
    for i, (h, w) in enumerate([(40, 72), (37, 61)]):
        write_image(images / f"{i:010d}.png", rng.integers(0, 256, (h, w, 3), dtype=np.uint8))
    out = tmp_path / "semantic"
    res = CliRunner().invoke(
        main,
        ["segment", "--model", f"hf:{tiny}", "--images", str(tmp_path / "raw"), "--out", str(out), "--device", "cpu"],
    )
    assert res.exit_code == 0, res.output
    for i, (h, w) in enumerate([(40, 72), (37, 61)]):
        sem = read_image(out / f"2011_09_26/d/image_02/data/{i:010d}.png")
        assert sem.shape == (h, w, 3) and _palette_only(sem)


def test_labels_are_matched_by_name_not_position(tmp_path: Path) -> None:
    folder = _save_tiny(tmp_path / "shuffled", VARIANTS, winner=0)  # model class 0 is "car"
    seg = load_segmenter(f"hf:{folder}", "cpu")
    ids = seg(np.zeros((2, 32, 48, 3), np.uint8))
    assert ids.shape == (2, 32, 48) and (ids == NAMES.index("car")).all()


def test_naming_variants_map_to_every_train_id() -> None:
    groups = cityscapes_indices(dict(enumerate(VARIANTS)))
    assert all(len(g) == 1 for g in groups)
    assert groups[NAMES.index("person")] == [VARIANTS.index("pedestrian")]
    assert groups[NAMES.index("train")] == [VARIANTS.index("on rails")]
    assert all(VARIANTS.index("unlabeled") not in g for g in groups)


def test_default_is_segformer_b5_cityscapes() -> None:
    rec = HF_SEGMENTERS["default"]
    assert resolve_hf_source("default") == ("nvidia/segformer-b5-finetuned-cityscapes-1024-1024", None)
    assert rec.cityscapes_val_miou == 82.4 and "non-commercial" in rec.license
    assert resolve_hf_source("org/name@v1") == ("org/name", "v1")


def test_offline_missing_model_is_one_line_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
    res = CliRunner().invoke(
        main, ["segment", "--model", "hf:no-such-org/no-such-model", "--images", ".", "--out", "unused"]
    )
    assert res.exit_code == 1 and "offline" in res.output and len(res.output.strip().splitlines()) == 1


def test_without_transformers_says_how_to_install(tiny: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "transformers", None)
    with pytest.raises(ValueError, match=r"semattnet\[segment\]"):
        load_segmenter(f"hf:{tiny}", "cpu")
