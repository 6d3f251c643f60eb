"""Cross-palette evaluation: a Cityscapes (KITTI) model scored on NYU v2 frames whose maps are NYU-40, with
``--palette-mismatch recolour`` (the classes both palettes name keep their meaning, the rest unknown) or
``fallback`` (the unknown map); metrics.json and the printed summary say which."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet.cli import main
from semattnet.palette import NYU40_CLASSES, TRAIN_CLASSES, colors_to_ids, ids_to_colors, palette_mapping, recolor

NYU = {name: i + 1 for i, (name, _) in enumerate(NYU40_CLASSES)}
CITY = {name: i for i, (name, _) in enumerate(TRAIN_CLASSES)}


def test_mapping_and_recolouring() -> None:
    assert palette_mapping("nyu40", "cityscapes") == {NYU["wall"]: CITY["wall"], NYU["person"]: CITY["person"]}
    assert palette_mapping("cityscapes", "nyu40") == {CITY["wall"]: NYU["wall"], CITY["person"]: NYU["person"]}
    nyu = ids_to_colors(np.array([[NYU["wall"], NYU["bed"]], [NYU["person"], 0]]), palette="nyu40")
    city = colors_to_ids(recolor(nyu, "nyu40", "cityscapes"))
    assert city.tolist() == [[CITY["wall"], 255], [CITY["person"], 255]]


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    pytest.importorskip("h5py")
    import semattnet
    from semattnet.weights.checkpoint import save_safetensors
    from tests.data._datasets import make_nyu

    t = tmp_path_factory.mktemp("cross")
    ckpt = t / "city.safetensors"  # no palette recorded: a Cityscapes (KITTI) model
    save_safetensors(semattnet.build_model("semattnet_backbone", width=0.125).state_dict(), ckpt)
    return make_nyu(t / "nyu", train=0, test=1, label=True), ckpt  # labels 1..4: wall, floor, cabinet, bed


@pytest.mark.parametrize("policy", ["recolour", "fallback"])
def test_kitti_model_on_nyu(policy: str, setup: tuple[Path, Path], tmp_path: Path) -> None:
    root, ckpt = setup
    res = CliRunner().invoke(
        main,
        [
            "evaluate",
            "--dataset",
            "nyuv2",
            "--data",
            str(root),
            "--checkpoint",
            str(ckpt),
            "--workers",
            "0",
            "--device",
            "cpu",
            "--palette-mismatch",
            policy,
            "--out",
            str(tmp_path / "ev"),
        ],
    )
    assert res.exit_code == 0, res.output + repr(res.exception)
    sem = json.loads((tmp_path / "ev" / "metrics.json").read_text())["semantic"]
    assert sem["maps_palette"] == "nyu40" and sem["model_palette"] == "cityscapes" and sem["used"] == policy
    if policy == "recolour":
        assert sem["classes_kept"] == ["person", "wall"] and "recoloured to the model's Cityscapes" in res.output
    else:
        assert sem["classes_kept"] == [] and "replaced by the fallback (unknown) map" in res.output


def test_recolouring_reaches_the_model(setup: tuple[Path, Path]) -> None:
    from semattnet.data.datasets import get_dataset
    from semattnet.data.sources.semantic import CrossPalette

    src = get_dataset("nyuv2").source(setup[0], "test")
    assert src.palette is not None
    cross = CrossPalette(src.palette, "cityscapes")
    semantic = src.load("00001").semantic
    assert semantic is not None
    ids = colors_to_ids(cross.map(semantic))  # Cityscapes colours now: wall kept, floor/cabinet/bed unknown
    assert set(np.unique(ids).tolist()) == {CITY["wall"], 255} and cross.palette == "cityscapes"


def test_predict_recolours_too(setup: tuple[Path, Path], tmp_path: Path) -> None:
    root, ckpt = setup
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
        "--palette-mismatch",
        "recolour",
        "--out",
        tmp_path / "p",
    ]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output + repr(res.exception)
    assert "semantic maps: NYU-40 maps recoloured to the model's Cityscapes palette: person, wall kept" in res.output
    assert (tmp_path / "p" / "00001.png").is_file()
