"""int8 calibration frames that cannot be used (a file, an empty folder, empty subfolders, a corrupt PNG, a frame
without a LiDAR point) are blamed on the calibration, not on the frames: one line naming ``--calibration`` and the
file, before any work, never "no frame could be completed" about every frame; in the library, a run error, not a
frame's fault (issue 48)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import SemAttNetError
from semattnet.cli import main
from semattnet.data.io import write_depth, write_image


def _one_line(fn: Callable[[], object], cls: type[Exception] = SemAttNetError) -> str:
    with pytest.raises(cls) as err:
        fn()
    assert "\n" not in str(err.value)
    return str(err.value)


def _frames(root: Path, sparse: float = 0.1) -> list[str]:
    """``root/{rgb,sparse}/f0.png``: one 64x96 frame (``sparse``: the share of pixels with a LiDAR point)."""
    rng = np.random.default_rng(0)
    for d in ("rgb", "sparse"):
        (root / d).mkdir(parents=True)
    write_image(root / "rgb" / "f0.png", rng.integers(0, 256, (64, 96, 3), dtype=np.uint8))
    write_depth(root / "sparse" / "f0.png", np.where(rng.random((64, 96)) < sparse, 9.0, 0).astype(np.float32))
    return [f"--rgb={root / 'rgb'}", f"--sparse={root / 'sparse'}"]


def _calibration_cases(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """What ``--calibration`` is given, and the words its refusal holds."""
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "a_file.txt").write_text("x")
    (tmp_path / "empty").mkdir()
    (tmp_path / "subs" / "rgb").mkdir(parents=True)
    (tmp_path / "subs" / "sparse").mkdir()
    _frames(tmp_path / "corrupt")
    (tmp_path / "corrupt" / "sparse" / "f0.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    _frames(tmp_path / "no_lidar", sparse=0.0)
    return {
        "file": (tmp_path / "a_file.txt", "is not a folder"),
        "empty folder": (tmp_path / "empty", "neither rgb/ + sparse/ subfolders nor a KITTI root"),
        "empty subfolders": (tmp_path / "subs", "no PNG images"),
        "corrupt PNG": (tmp_path / "corrupt", "corrupt/sparse/f0.png"),
        "no LiDAR point": (tmp_path / "no_lidar", "has no LiDAR point"),
    }


@pytest.mark.parametrize("case", ["file", "empty folder", "empty subfolders", "corrupt PNG", "no LiDAR point"])
def test_int8_calibration_is_blamed_not_the_frames(tmp_path: Path, case: str) -> None:
    calibration, words = _calibration_cases(tmp_path)[case]
    frames = _frames(tmp_path / "frames")
    res = CliRunner().invoke(
        main,
        [
            "predict",
            *frames,
            "--weights",
            "semattnet-demo-ref-seed0",
            "--backend",
            "openvino",
            "--precision",
            "int8",
            "--calibration",
            str(calibration),
            "--out",
            str(tmp_path / "out"),
        ],
    )
    lines = [x for x in res.output.splitlines() if x.strip() and not x.startswith(("Usage: ", "Try '"))]
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert "'--calibration'" in lines[0] and words in lines[0] and "frame could be completed" not in lines[0]
    assert not (tmp_path / "out").exists()


def test_calibration_errors_are_the_runs_not_a_frames(tmp_path: Path) -> None:
    from semattnet.inference.backends.calibration import CalibrationError, resolve_calibration
    from semattnet.inference.feed import is_frame_fault

    calibration, _ = _calibration_cases(tmp_path)["corrupt PNG"]
    message = _one_line(lambda: resolve_calibration(calibration, (64, 96)), CalibrationError)
    assert str(calibration / "sparse" / "f0.png") in message
    with pytest.raises(CalibrationError) as err:
        resolve_calibration(_calibration_cases(tmp_path / "b")["no LiDAR point"][0], (64, 96))
    assert not is_frame_fault(err.value)  # a library run stops on it, not skipping every frame
