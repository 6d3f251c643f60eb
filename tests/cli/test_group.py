"""The CLI's error handling (``cli/_group.py``): bad input is one line, anything else is a bug report."""

from __future__ import annotations

import errno
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

import semattnet.segmentation.segmenter as segmenter_module
from semattnet import DataError, InputError, MissingDependencyError
from semattnet.cli import main
from semattnet.cli._group import BUG_EXIT_CODE, bug_report_line
from semattnet.weights import UnsafeCheckpointError


def _segment(tmp_path: Path, model: str = "unknown") -> Result:
    images = tmp_path / "images"
    images.mkdir(exist_ok=True)
    args = ["segment", "--model", model, "--images", str(images), "--out", str(tmp_path / "o")]
    return CliRunner().invoke(main, args)


def _raising(exc: BaseException) -> Callable[..., None]:
    """A stand-in for a library call that raises ``exc``."""

    def fail(*args: object, **kwargs: object) -> None:
        raise exc

    return fail


def _one_line_error(result: Result) -> str:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    return lines[0]


def test_real_data_error_is_one_line(tmp_path: Path) -> None:
    """End to end: a model file that does not exist (DataError raised by load_segmenter)."""
    line = _one_line_error(_segment(tmp_path, str(tmp_path / "missing.onnx")))
    assert f"{tmp_path / 'missing.onnx'}: no such model file" in line


def test_real_data_error_from_an_empty_folder(tmp_path: Path) -> None:
    line = _one_line_error(_segment(tmp_path))
    assert f"{tmp_path / 'images'}: no " in line and "images found" in line


@pytest.mark.parametrize(
    "exc",
    [
        DataError("/data/x.png: not a 16-bit PNG"),
        InputError("rgb must have 3 channel(s), got shape (1, 4, 8, 8)"),
        MissingDependencyError("ONNX models need onnxruntime (pip install onnxruntime)"),
        UnsafeCheckpointError("/w.pth: refusing to load: the pickle calls os.system, which could run code"),
    ],
)
def test_library_errors_are_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exc: Exception) -> None:
    monkeypatch.setattr(segmenter_module, "segment_folder", _raising(exc))
    assert _one_line_error(_segment(tmp_path)) == f"Error: {exc}"


def test_os_error_is_one_line_with_the_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    exc = PermissionError(errno.EACCES, "Permission denied", "/read-only/out/a.png")
    monkeypatch.setattr(segmenter_module, "segment_folder", _raising(exc))
    line = _one_line_error(_segment(tmp_path))
    advice = "check the folder's permissions or choose another --out"
    assert line == f"Error: /read-only/out/a.png: Permission denied ({advice})"


@pytest.mark.parametrize("exc", [RuntimeError("boom in a kernel"), ValueError("a bare ValueError of ours")])
def test_other_exceptions_are_a_traceback_and_a_bug_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, exc: Exception
) -> None:
    monkeypatch.setattr(segmenter_module, "segment_folder", _raising(exc))
    result = _segment(tmp_path)
    assert result.exit_code == BUG_EXIT_CODE != 0
    err = result.stderr
    assert err.startswith("Traceback (most recent call last):"), err
    assert f"{type(exc).__name__}: {exc}" in err and "in fail" in err  # the real traceback, down to the raise
    last = err.strip().splitlines()[-1]
    assert last == bug_report_line(exc)
    assert f"{type(exc).__name__} is a bug in semattnet" in last and "report it at" in last


def test_click_usage_errors_are_untouched(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["segment", "--model", "unknown"])
    assert result.exit_code == 2 and "Missing option" in result.output and "Traceback" not in result.output
