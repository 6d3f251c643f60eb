"""The demo's shipped reference checkpoint (quantised storage, its record, --train-reference) and the
demo-only L1 + L2 loss."""

from __future__ import annotations

import dataclasses
import gzip
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

from semattnet._errors import DataError, InputError
from semattnet.apps.demo import reference as ref
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.registry import build_model
from semattnet.training.config import TrainConfig
from semattnet.training.losses import masked_l1, masked_mse, semattnet_loss


def test_quantise_per_output_channel_by_hand() -> None:
    w = torch.tensor([[1.0, -0.3, 0.25], [0.0, 0.01, -0.04]]).reshape(2, 3, 1, 1)
    q = ref.quantise({"conv.weight": w, "bn.bias": torch.tensor([0.1, 0.2]), "bn.n": torch.tensor(3)})
    assert q["q8/conv.weight"].dtype == torch.int8
    assert q["scale/conv.weight"].tolist() == pytest.approx([1.0 / 127, 0.04 / 127])
    assert q["q8/conv.weight"].flatten().tolist() == [127, -38, 32, 0, 32, -127]  # -38.1, 31.75, 31.75
    assert q["f16/bn.bias"].dtype == torch.float16 and q["raw/bn.n"].item() == 3
    back = ref.dequantise(q)
    expected = [1.0, -38 / 127, 32 / 127, 0.0, 0.04 * 32 / 127, -0.04]
    assert back["conv.weight"].flatten().tolist() == pytest.approx(expected, abs=1e-4)
    assert ref.quantise({"w": w}, levels=31)["q8/w"].flatten().tolist() == [31, -9, 8, 0, 8, -31]  # -9.3, 7.75, 7.75


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(0)
    model = build_model("semattnet", width=0.125).eval()
    path = ref.save_reference(model, tmp_path / "r.safetensors.gz", {"command": "x", "recipe": {}}, levels=127)
    loaded, info = ref.load_reference(path)
    assert info == {"command": "x", "recipe": {}}
    x = {
        "rgb": torch.rand(1, 3, 32, 64) * 255,
        "semantic": torch.rand(1, 3, 32, 64) * 255,
        "sparse": torch.rand(1, 1, 32, 64) * 40 * (torch.rand(1, 1, 32, 64) < 0.1),
    }
    with torch.no_grad():
        a, b = model(**x).refined_depth, loaded(**x).refined_depth
    assert 0 < (a - b).abs().mean() < 0.05 * a.abs().mean()  # int8 weights: close on average, not equal
    for name, t in model.state_dict().items():
        if t.is_floating_point() and t.dim() >= 2:  # each weight within half a quantisation step
            step = t.reshape(t.shape[0], -1).abs().amax(1) / 127
            err = (loaded.state_dict()[name] - t).reshape(t.shape[0], -1).abs().amax(1)
            assert (err <= step / 2 + 1e-6).all(), name


def test_bad_reference_files_are_refused_with_the_name(tmp_path: Path) -> None:
    bad = tmp_path / "bad.gz"
    bad.write_bytes(b"not gzip at all")
    with pytest.raises(ref.ReferenceError, match=r"bad\.gz: not a readable demo reference"):
        ref.load_reference(bad)
    from safetensors.torch import save

    other = tmp_path / "other.gz"
    other.write_bytes(gzip.compress(save({"a": torch.zeros(1)}, metadata={"format": "else"})))
    with pytest.raises(DataError, match=r"other\.gz: .*not packed weights \(format 'else', expected 'semattnet-demo"):
        ref.load_reference(other)
    with pytest.raises(ref.ReferenceError, match="missing.gz"):
        ref.load_reference(tmp_path / "missing.gz")


@pytest.mark.parametrize("seed", ref.REFERENCE_SEEDS)
def test_the_shipped_references_are_small_load_and_record_their_recipe(seed: int) -> None:
    path = ref.reference_path(seed)
    assert path.is_file(), "the repository ships one reference checkpoint per seed of REFERENCE_SEEDS"
    assert path.stat().st_size < 5_000_000 and ref.shipped_references()[seed] == path
    model, info = ref.load_reference(path)
    assert model.config.branches == 3 and model.config.refine and model.config.width == info["recipe"]["width"]
    recipe = dataclasses.replace(ref.REFERENCE_RECIPE, seed=seed)
    recorded = {"semantic_dropout": 0.0} | info["recipe"]  # files trained before the field had none
    assert recorded == dataclasses.asdict(recipe) | {"size": list(recipe.size)}
    assert info["command"] == ref.REFERENCE_COMMAND and info["levels"] in ref.LEVELS
    assert {"reference", "classical"} <= set(info["val"]) <= {"reference", "reference_fallback_map", "classical"}
    notes = ref.recipe_notes(info["recipe"])
    assert "data seed 1000" in notes[0] and "L1 + L2" in notes[1] and "seed 0, 1" in notes[0]


def test_train_reference_tiny_recipe(tmp_path: Path) -> None:
    """The whole --train-reference path on a tiny recipe: three stages, then the packaged file."""
    tiny = dataclasses.replace(
        ref.REFERENCE_RECIPE,
        train_frames=4,
        val_frames=2,
        size=(32, 64),
        batch_size=2,
        backbone_steps=2,
        refine_init_steps=1,
        full_steps=1,
        semantic_dropout=0.5,
    )
    lines: list[str] = []
    target = ref.train_reference(tmp_path / "work", tmp_path / "out.safetensors.gz", tiny, log=lines.append)
    for stage in ("backbone", "refine_init", "full"):
        assert (tmp_path / "work" / "run" / stage / "checkpoints" / "last.pt").is_file(), stage
    refine_init = TrainConfig.load(tmp_path / "work" / "run" / "refine_init" / "config.json")
    assert refine_init.stage == "refine-init" and refine_init.lr == pytest.approx(tiny.lr * tiny.head_lr_factor)
    assert refine_init.loss == "l1+l2" and refine_init.semantic_dropout == 0.5
    full = TrainConfig.load(tmp_path / "work" / "run" / "full" / "config.json")
    assert full.lr == pytest.approx(tiny.lr / 4) and full.head_lr == pytest.approx(tiny.lr * tiny.head_lr_factor)
    _, info = ref.load_reference(target)
    assert info["recipe"]["backbone_steps"] == 2 and info["levels"] in ref.LEVELS and "written" in lines[-1]
    assert set(info["val"]) == {"reference", "reference_fallback_map", "classical"}  # scored with the fallback map too
    assert info["command"] == f"{ref.REFERENCE_COMMAND} --semantic-dropout 0.5"  # the command that remakes it


def test_cli_train_reference_refuses_a_non_empty_folder(tmp_path: Path) -> None:
    from semattnet.cli import main

    (tmp_path / "keep.txt").write_text("x")
    res = CliRunner().invoke(main, ["demo", "--train-reference", "--out", str(tmp_path)])
    assert res.exit_code != 0 and "not empty" in res.output
    assert (tmp_path / "keep.txt").read_text() == "x"


def test_cli_semantic_dropout_belongs_to_train_reference(tmp_path: Path) -> None:
    from semattnet.cli import main

    res = CliRunner().invoke(main, ["demo", "--out", str(tmp_path / "demo"), "--semantic-dropout", "0.5"])
    assert res.exit_code == 2 and "--semantic-dropout is an option of --train-reference" in res.output
    assert not (tmp_path / "demo").exists()
    assert ref.reference_command(ref.REFERENCE_RECIPE) == ref.REFERENCE_COMMAND  # no dropout: the shipped command


def _out(refined: torch.Tensor | None, fused: torch.Tensor) -> DepthCompletionOutput:
    ones = torch.ones_like(fused)
    return DepthCompletionOutput(
        color_depth=fused,
        semantic_depth=fused,
        guided_depth=fused,
        color_conf=ones,
        semantic_conf=ones,
        guided_conf=ones,
        fused_depth=fused,
        refined_depth=refined,
    )


def test_l1_plus_l2_loss_by_hand() -> None:
    gt = torch.tensor([[[[10.0, 0.0, 20.0, 5.0]]]])  # one pixel without ground truth
    pred = torch.tensor([[[[12.0, 99.0, 19.0, 5.0]]]])
    assert masked_l1(pred, gt).item() == pytest.approx((2 + 1 + 0) / 3)
    assert masked_mse(pred, gt).item() == pytest.approx((4 + 1 + 0) / 3)
    out = _out(pred, gt)
    assert semattnet_loss(out, gt, loss="l1+l2").item() == pytest.approx(3 / 3 + 5 / 3)
    assert semattnet_loss(out, gt).item() == pytest.approx(5 / 3)  # the paper's L2
    backbone = _out(None, pred)  # (1 - 3w) L(fused) + w * 3 L(branch), all equal: L(pred)
    assert semattnet_loss(backbone, gt, 0.2, "l1+l2").item() == pytest.approx(8 / 3)
    with pytest.raises(InputError, match="loss must be one of"):
        semattnet_loss(out, gt, loss="l1")
    with pytest.raises(ValueError, match="loss must be one of"):
        TrainConfig(loss="huber")
