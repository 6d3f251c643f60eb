"""hubconf.py through torch.hub.load(source="local")."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from semattnet.weights import save_pretrained
from semattnet.weights.checkpoint import CheckpointError

from .conftest import Server, predict

REPO = Path(__file__).resolve().parents[2]


def test_hubconf_declares_installed_dependencies() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("hubconf_under_test", REPO / "hubconf.py")
    hubconf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hubconf)
    assert str(REPO / "src") in __import__("sys").path  # src layout put on sys.path
    assert {"torch", "safetensors"} <= set(hubconf.dependencies)
    assert all(importlib.util.find_spec(dep) for dep in hubconf.dependencies)
    assert callable(hubconf.semattnet) and callable(hubconf.semattnet_backbone)


def test_load_without_weights() -> None:
    model = torch.hub.load(str(REPO), "semattnet", source="local", pretrained=False, width=0.125)
    assert type(model).__name__ == "SemAttNet" and model.config.width == 0.125
    backbone = torch.hub.load(str(REPO), "semattnet_backbone", source="local", width=0.125)
    assert type(backbone).__name__ == "SemAttNetBackbone"


def test_load_weights_from_local_url(
    tmp_path: Path, server: Server, cache: Path, tiny_model, tiny_inputs, expected
) -> None:
    folder = save_pretrained(tiny_model, tmp_path / "export")
    url = server.add("/w/model.safetensors", (folder / "model.safetensors").read_bytes())
    model = torch.hub.load(str(REPO), "semattnet", source="local", pretrained=url, progress=False)
    assert not model.training
    assert torch.equal(predict(model, tiny_inputs), expected)
    # A local path works too, and full-model weights are refused by the backbone entry point.
    with pytest.raises(CheckpointError, match="full model"):
        torch.hub.load(str(REPO), "semattnet_backbone", source="local", pretrained=str(folder))


def test_backbone_has_no_default_weights() -> None:
    with pytest.raises(ValueError, match="no released weights for 'semattnet_backbone'"):
        torch.hub.load(str(REPO), "semattnet_backbone", source="local", pretrained=True)


def test_default_weights_offline_name_the_authors_file(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from semattnet.weights import OfflineError

    monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
    with pytest.raises(OfflineError) as err:
        torch.hub.load(str(REPO), "semattnet", source="local", pretrained=True)
    msg = str(err.value)
    assert "model_best_backup.pth.tar" in msg and "gdrive://1plg4zGCLYndP0xtkh_gjG1RZ4YzPeiDN" in msg
    assert str(cache / "semattnet-kitti" / "model_best_backup.pth.tar") in msg
