"""The public API stays importable under its documented names (README, issue contracts)."""

from __future__ import annotations

import importlib

import pytest

import semattnet
from semattnet import SemAttNetError


def test_top_level_names() -> None:
    for name in (
        "build_model",
        "list_models",
        "from_pretrained",
        "pad_to_multiple",
        "crop_padding",
        "DepthCompleter",
        "SemAttNetConfig",
        "DepthCompletionOutput",
        "palette",
    ):
        assert hasattr(semattnet, name), name
    assert set(semattnet.__all__) <= set(dir(semattnet))


def test_one_loader_at_the_root_the_others_in_weights_with_a_deprecation_window() -> None:
    import semattnet.weights

    assert not {"load_model", "load_checkpoint", "load_weights", "get_weights"} & set(semattnet.__all__)
    for name in ("load_checkpoint", "load_weights", "get_weights"):
        with pytest.warns(DeprecationWarning, match=f"semattnet.{name} is deprecated since 0.2.*semattnet.weights"):
            assert getattr(semattnet, name) is getattr(semattnet.weights, name)
    with pytest.warns(DeprecationWarning, match="use semattnet.from_pretrained"):
        semattnet.load_model  # noqa: B018
    with pytest.raises(AttributeError):
        semattnet.no_such_loader  # noqa: B018


def test_palette_is_its_own_module() -> None:
    from semattnet.palette import PALETTE, colors_to_ids

    assert PALETTE.shape == (19, 3) and callable(colors_to_ids)
    assert semattnet.palette is importlib.import_module("semattnet.palette")
    assert importlib.import_module("semattnet.palette").__file__.endswith("palette/__init__.py")


@pytest.mark.parametrize(
    "path",
    [
        "semattnet.data.io.DataError",
        "semattnet.palette.UnknownColorError",
        "semattnet.weights.CheckpointError",
        "semattnet.weights.StateDictMismatchError",
        "semattnet.weights.UnsafeCheckpointError",
        "semattnet.evaluation.SubmissionError",
        "semattnet.DataError",
        "semattnet.InputError",
        "semattnet.MissingDependencyError",
    ],
)
def test_errors_share_one_root(path: str) -> None:
    module, name = path.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    assert issubclass(cls, SemAttNetError) and issubclass(cls, ValueError)


def test_error_roots_keep_their_builtin_bases() -> None:
    """``except TypeError`` / ``except ImportError`` code keeps catching the argument / dependency errors."""
    assert issubclass(semattnet.InputError, TypeError) and issubclass(semattnet.MissingDependencyError, ImportError)
    assert semattnet.data.io.DataError is semattnet.DataError is semattnet.data.DataError
    missing = semattnet.MissingDependencyError("needs onnx: pip install onnx", name="onnx")
    assert missing.name == "onnx" and str(missing) == "needs onnx: pip install onnx"


def test_scan_file_names_live_in_data_only() -> None:
    """geometry sits below data in the layer table: the old aliases into data are gone."""
    import semattnet.data.scans as scans
    import semattnet.geometry as geometry

    for name in ("project_scan_file", "ProjectionSummary"):
        assert hasattr(scans, name) and not hasattr(geometry, name)
