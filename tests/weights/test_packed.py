"""Packed weights (quantised, gzip'd safetensors): read by their bytes wherever weights are read, the
shipped ones by registry name, and hostile or broken files refused in one line naming the file."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

import semattnet
from semattnet.cli import main
from semattnet.models.registry import build_model
from semattnet.weights import CheckpointError, WeightsMismatchError, load_checkpoint
from semattnet.weights import packed as packed_mod
from semattnet.weights.hub import load_model, save_pretrained


def _model() -> torch.nn.Module:
    torch.manual_seed(0)
    return build_model("semattnet", width=0.125).eval()


def test_a_packed_file_is_read_by_its_bytes_with_config_and_record(tmp_path: Path) -> None:
    model = _model()
    path = packed_mod.save_packed(model, tmp_path / "mine.bin", {"trained": "here"}, levels=127)
    ckpt = load_checkpoint(path)  # no .gz in the name: the gzip magic decides
    assert ckpt.format == "packed" and ckpt.config == model.config and ckpt.extra["info"] == {"trained": "here"}
    loaded = load_model(path)
    for name, t in model.state_dict().items():
        got = loaded.state_dict()[name]
        if t.is_floating_point() and t.dim() >= 2:  # within half a step of 127 levels per output channel
            step = t.reshape(t.shape[0], -1).abs().amax(1) / 127
            assert ((got - t).reshape(t.shape[0], -1).abs().amax(1) <= step / 2 + 1e-6).all(), name
        elif t.is_floating_point():
            assert torch.allclose(got, t, rtol=1e-3, atol=1e-4), name  # float16
        else:
            assert torch.equal(got, t), name


def test_hostile_and_broken_packed_files_are_refused_naming_the_file(tmp_path: Path, monkeypatch) -> None:
    model = _model()
    good = packed_mod.save_packed(model, tmp_path / "good.gz", {})
    cut = tmp_path / "cut.gz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(CheckpointError, match=r"cut\.gz: truncated gzip stream"):
        load_checkpoint(cut)
    junk = tmp_path / "junk.gz"
    junk.write_bytes(gzip.compress(b"\x00" * 64))
    with pytest.raises(CheckpointError, match=r"junk\.gz: gzip of something that is not safetensors"):
        load_checkpoint(junk)
    notgz = tmp_path / "notgz.gz"
    notgz.write_bytes(b"\x1f\x8b" + b"not really gzip")
    with pytest.raises(CheckpointError, match=r"notgz\.gz: not a readable packed weights file"):
        load_checkpoint(notgz)
    monkeypatch.setattr(packed_mod, "MAX_UNPACKED_BYTES", 1 << 20)  # a gzip bomb stops at the bound
    with pytest.raises(CheckpointError, match=r"good\.gz: unpacks to more than 1 MiB"):
        load_checkpoint(good)


def test_a_stray_tensor_name_is_refused(tmp_path: Path) -> None:
    from safetensors.torch import save

    meta = {"format": packed_mod.PACKED_FORMAT, "config": "{}", "info": "{}"}
    odd = tmp_path / "odd.gz"
    odd.write_bytes(gzip.compress(save({"q8/w": torch.zeros(2, 2, dtype=torch.int8)}, metadata=meta)))
    with pytest.raises(CheckpointError, match=r"odd\.gz: tensor 'q8/w' has no scale"):
        load_checkpoint(odd)


def test_load_model_takes_a_save_pretrained_folder_and_a_name(tmp_path: Path) -> None:
    model = _model()
    folder = save_pretrained(model, tmp_path / "folder")
    loaded = semattnet.from_pretrained(folder)
    assert all(
        torch.equal(a, b) for a, b in zip(model.state_dict().values(), loaded.state_dict().values(), strict=True)
    )
    assert semattnet.from_pretrained("semattnet-demo-ref-seed1").config.width == 0.125


@pytest.mark.slow  # packing and reading 5.7 M parameters: ~8 s on 2 cores; test_builder checks the rule fast
def test_a_packed_file_whose_config_contradicts_its_tensors_is_refused_beside_a_record(tmp_path: Path) -> None:
    model = _model()
    folder = save_pretrained(model, tmp_path / "folder")  # config.json: the record, true to the tensors
    lying = model.config.replace(width=0.25).to_dict()
    (folder / "model.safetensors").write_bytes(packed_mod.encode_packed(model.state_dict(), lying, {}))
    with pytest.raises(WeightsMismatchError) as err:
        semattnet.from_pretrained(folder)
    assert "config in the file's metadata contradicts the weights: width 0.25 recorded" in str(err.value)
    assert str(folder / "model.safetensors") in str(err.value) and "\n" not in str(err.value)


def test_info_takes_a_shipped_name() -> None:
    res = CliRunner().invoke(main, ["info", "--weights", "semattnet-demo-ref-seed0"])
    assert res.exit_code == 0, res.output
    assert "packed" in res.output or "0.125" in res.output
