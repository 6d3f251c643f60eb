"""The weights registry: a schema check over every record, lookups and errors."""

from __future__ import annotations

import pytest

from semattnet.weights import PretrainedWeights, UnknownWeightsError, get_weights, list_pretrained
from semattnet.weights.pretrained import DEFAULT_WEIGHTS, default_weights, register_weights

UNITS = ("_mm", "_m", "_per_km", "_pct")
INPUT_KEYS = {"rgb", "semantic", "sparse", "size_multiple"}


def test_authors_release() -> None:
    w = get_weights("semattnet-kitti")
    assert w.urls[0] == "gdrive://1plg4zGCLYndP0xtkh_gjG1RZ4YzPeiDN"
    assert w.format == "authors-pth" and w.file_name == "model_best_backup.pth.tar" and w.arch == "semattnet"
    assert dict(w.paper_metrics["kitti/test"]) == {
        "rmse_mm": 709.41,
        "mae_mm": 205.49,
        "irmse_per_km": 2.03,
        "imae_per_km": 0.90,
    }
    assert w.doi == "10.1109/ACCESS.2022.3214316"
    assert w.num_params == 360_957_784  # spec ARCHITECTURE.md
    assert "semattnet-kitti-backbone" not in list_pretrained()  # the authors released no backbone weights
    assert default_weights("semattnet") is w and DEFAULT_WEIGHTS == {"semattnet": "semattnet-kitti"}


def test_records_are_read_only() -> None:
    w = get_weights("semattnet-kitti")
    with pytest.raises(TypeError):
        w.paper_metrics["kitti/test"]["rmse_mm"] = 1.0  # type: ignore[index]
    with pytest.raises(AttributeError):
        w.sha256 = "0" * 64  # type: ignore[misc]
    assert hash(w) == hash("semattnet-kitti")


def test_unknown_name_is_one_line_listing_known() -> None:
    with pytest.raises(UnknownWeightsError) as err:
        get_weights("semattnet-nyu")
    assert str(err.value) == "unknown pretrained weights 'semattnet-nyu'; available: " + ", ".join(list_pretrained())
    with pytest.raises(UnknownWeightsError, match="released only the full model"):
        default_weights("semattnet_backbone")


def test_register_rejects_duplicates_and_unknown_arch() -> None:
    with pytest.raises(ValueError, match="already registered"):
        register_weights(get_weights("semattnet-kitti"))
    bad = PretrainedWeights(name="x", arch="resnet", urls=("https://e/x",), file_name="x", format="torch", license="l")
    with pytest.raises(ValueError, match="unknown arch 'resnet'"):
        register_weights(bad)
