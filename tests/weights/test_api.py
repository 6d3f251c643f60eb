"""from_pretrained / save_pretrained / push_to_hub: names, files, folders, URLs, hf://, safety."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import types
from pathlib import Path

import pytest
import torch

import semattnet
from semattnet.weights import (
    DownloadError,
    OfflineError,
    PretrainedWeights,
    from_pretrained,
    read_pins,
    save_pretrained,
)
from semattnet.weights import hub as hub_api
from semattnet.weights.builder import WeightsMismatchError
from semattnet.weights.checkpoint import CheckpointError, StateDictMismatchError, UnsafeCheckpointError

from .conftest import Server, cache_files, predict


def _authors_pickle(path: Path, state_dict: dict) -> Path:
    """A checkpoint written the way the authors' code did: their own classes pickled inside."""
    metrics = types.ModuleType("metrics")

    class Result:
        def __init__(self) -> None:
            self.rmse = 0.709

    Result.__module__, Result.__qualname__ = "metrics", "Result"
    metrics.Result = Result  # type: ignore[attr-defined]
    sys.modules["metrics"] = metrics
    try:
        torch.save(
            {
                "epoch": 95,
                "model": state_dict,
                "best_result": Result(),
                "optimizer": {"state": {}},
                "args": argparse.Namespace(lr=0.00128),
            },
            path,
        )
    finally:
        del sys.modules["metrics"]
    return path


def test_save_pretrained_folder_round_trip(tmp_path: Path, tiny_model, tiny_inputs, expected) -> None:
    folder = save_pretrained(tiny_model, tmp_path / "export", weights="semattnet-kitti")
    assert sorted(p.name for p in folder.iterdir()) == ["README.md", "config.json", "model.safetensors"]
    config = json.loads((folder / "config.json").read_text())
    assert config["arch"] == "semattnet" and config["width"] == 0.125
    assert config["library_version"] == semattnet.__version__
    card = (folder / "README.md").read_text()
    assert "library_name: semattnet" in card and "709.41" in card and "licence" in card
    loaded = from_pretrained(folder)
    assert not loaded.training and loaded.config == tiny_model.config
    assert torch.equal(predict(loaded, tiny_inputs), expected)
    assert torch.equal(predict(from_pretrained(str(folder / "model.safetensors")), tiny_inputs), expected)


def test_folder_with_bad_config_is_refused(tmp_path: Path, tiny_model) -> None:
    folder = save_pretrained(tiny_model, tmp_path / "export")
    config = json.loads((folder / "config.json").read_text())
    (folder / "config.json").write_text(json.dumps({**config, "depth_scale": 2}))
    with pytest.raises(CheckpointError, match="unknown config field.*depth_scale"):
        from_pretrained(folder)
    (folder / "model.safetensors").unlink()
    with pytest.raises(CheckpointError, match="no model.safetensors"):
        from_pretrained(folder)


def _hf_cache_with(repo_id: str, folder: Path, hf_cache: Path) -> None:
    """Lay out a Hugging Face cache entry (refs/main -> snapshots/<commit>/...) as huggingface_hub does."""
    repo = hf_cache / f"models--{repo_id.replace('/', '--')}"
    commit = "0123456789abcdef0123456789abcdef01234567"
    (repo / "refs").mkdir(parents=True)
    (repo / "refs" / "main").write_text(commit)
    shutil.copytree(folder, repo / "snapshots" / commit)


def test_hf_url_through_huggingface_hub_cache(
    tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch, tiny_model, tiny_inputs, expected
) -> None:
    pytest.importorskip("huggingface_hub")
    folder = save_pretrained(tiny_model, tmp_path / "export")
    _hf_cache_with("someone/semattnet-tiny", folder, cache / "huggingface")
    # Offline: huggingface_hub (local_files_only) resolves refs/main and the snapshot from its cache.
    monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
    model = from_pretrained("hf://someone/semattnet-tiny")
    assert torch.equal(predict(model, tiny_inputs), expected)
    single = from_pretrained("hf://someone/semattnet-tiny/model.safetensors")
    assert torch.equal(predict(single, tiny_inputs), expected)
    with pytest.raises(OfflineError, match="someone/other"):
        from_pretrained("hf://someone/other")


def test_push_to_hub_uploads_a_loadable_folder(tmp_path: Path, monkeypatch, tiny_model, tiny_inputs, expected) -> None:
    huggingface_hub = pytest.importorskip("huggingface_hub")
    monkeypatch.delenv("SEMATTNET_OFFLINE", raising=False)
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    uploaded = tmp_path / "uploaded"
    calls: list[tuple] = []

    class FakeApi:
        def __init__(self, token=None) -> None:
            calls.append(("init", token))

        def create_repo(self, repo_id, **kwargs):
            calls.append(("create_repo", repo_id, kwargs["exist_ok"], kwargs["private"]))

        def upload_folder(self, *, repo_id, folder_path, **kwargs):
            calls.append(("upload_folder", repo_id, kwargs["commit_message"]))
            shutil.copytree(folder_path, uploaded)
            return "commit-info"

    monkeypatch.setattr(huggingface_hub, "HfApi", FakeApi)
    out = semattnet.weights.push_to_hub(tiny_model, "me/tiny", private=True, token="t", commit_message="m")
    assert out == "commit-info"
    assert calls == [("init", "t"), ("create_repo", "me/tiny", True, True), ("upload_folder", "me/tiny", "m")]
    assert torch.equal(predict(from_pretrained(uploaded), tiny_inputs), expected)


def test_authors_pickle_by_url_is_converted_once(
    tmp_path: Path, server: Server, cache: Path, monkeypatch: pytest.MonkeyPatch, tiny_model, tiny_inputs, expected
) -> None:
    pth = _authors_pickle(tmp_path / "model_best_backup.pth.tar", tiny_model.state_dict())
    entry = PretrainedWeights(
        name="tiny-authors",
        arch="semattnet",
        config={"width": 0.125, "iterations": 2},
        format="authors-pth",
        license="test",
        urls=(server.add("/w/model_best_backup.pth.tar", pth.read_bytes()),),
        file_name="model_best_backup.pth.tar",
    )
    reads: list[str] = []
    real_load = torch.load

    def spy(f, *args, **kwargs):
        reads.append(str(f))
        return real_load(f, *args, **kwargs)

    monkeypatch.setattr(torch, "load", spy)
    first = from_pretrained(entry)
    assert [Path(r).name for r in reads] == ["model_best_backup.pth.tar"]
    digest = read_pins()["tiny-authors/model_best_backup.pth.tar"]["sha256"]
    converted = cache / "converted" / f"{digest}.safetensors"
    assert converted.is_file() and read_pins()[f"converted/{digest}.safetensors"]["trust"] == "converted"
    reads.clear()
    second = from_pretrained(entry)
    assert reads == []  # the safetensors copy was read, not the pickle
    assert torch.equal(predict(first, tiny_inputs), expected) and torch.equal(predict(second, tiny_inputs), expected)
    assert len(server.gets("/w/model_best_backup.pth.tar")) == 1


def test_torch_checkpoint_by_url_and_offline(
    server: Server, cache: Path, monkeypatch, tiny_model, tiny_inputs, expected
) -> None:
    src = cache.parent / "ours.pt"
    torch.save({"model": tiny_model.state_dict(), "config": tiny_model.config.to_dict()}, src)
    url = server.add("/w/ours.pt", src.read_bytes())
    model = from_pretrained(url, map_location="cpu")
    assert torch.equal(predict(model, tiny_inputs), expected)
    server.stop()
    monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
    again = from_pretrained(url)
    assert torch.equal(predict(again, tiny_inputs), expected)
    assert from_pretrained(url, refinement_mode="clean").config.refinement_mode == "clean"


class _Evil:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os.system, (f"touch {self.marker}",))


def test_malicious_pickle_over_http_is_refused(server: Server, cache: Path, tmp_path: Path, tiny_model) -> None:
    marker = tmp_path / "pwned"
    evil = tmp_path / "evil.pth.tar"
    torch.save({"model": tiny_model.state_dict(), "epoch": _Evil(marker)}, evil)
    url = server.add("/w/evil.pth.tar", evil.read_bytes())
    with pytest.raises(UnsafeCheckpointError, match="system"):
        from_pretrained(url)
    assert not marker.exists()
    assert cache_files(cache) == [] and read_pins() == {}  # the download was removed, nothing converted


def test_not_a_checkpoint_is_refused_and_removed(server: Server, cache: Path) -> None:
    url = server.add("/w/page.pth.tar", b"<html>quota exceeded</html>")
    with pytest.raises(DownloadError, match="sent a web page"):  # refused by the cache before the gate
        from_pretrained(url)
    assert cache_files(cache) == []
    bin_url = server.add("/w/junk.pth.tar", b"\x00\x01 not a checkpoint at all")
    with pytest.raises(CheckpointError, match="not a readable"):  # not a page, but no checkpoint either
        from_pretrained(bin_url)
    assert cache_files(cache) == []


def test_unknown_source_is_one_line() -> None:
    with pytest.raises(ValueError) as err:
        from_pretrained("semattnet-kitty")
    assert "\n" not in str(err.value) and "semattnet-kitti" in str(err.value)


def test_registry_arch_mismatch_is_refused(tmp_path: Path, cache: Path, tiny_model) -> None:
    folder = save_pretrained(tiny_model, tmp_path / "export")
    entry = PretrainedWeights(
        name="wrong",
        arch="semattnet",
        config={"width": 0.25},
        format="safetensors",
        license="t",
        urls=((folder / "model.safetensors").as_uri(),),
        file_name="model.safetensors",
    )
    with pytest.raises(StateDictMismatchError) as err:  # the record is checked against the tensors' shapes
        hub_api.from_pretrained(entry)
    assert isinstance(err.value, WeightsMismatchError) and "\n" not in str(err.value)
    assert "weights 'wrong'" in str(err.value) and "width 0.25 recorded, 0.125 in the tensors" in str(err.value)
