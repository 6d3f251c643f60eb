"""The Python side of raw-drive completion: RawDrive frames, frame specs, complete_kitti_raw vs the CLI."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet import InputError
from semattnet.data.io import DataError, read_depth
from semattnet.data.kitti.raw import RawDrive, parse_frames
from semattnet.inference.raw import RawDriveSelection, complete_kitti_raw, fusion_confidence
from tests.inference._raw_sample import DRIVE, SCAN


def test_raw_drive_yields_typed_frames() -> None:
    drive = RawDrive(DRIVE, camera=3)
    assert drive.names == ["0000000005"] and len(drive) == 1
    (frame,) = list(drive)
    assert frame.name == "0000000005" and frame.index == 5 and frame.calib.camera == "03"
    assert frame.image.shape == (375, 1242, 3) and frame.image_path.parent.parent.name == "image_03"
    assert frame.points.shape == (SCAN.stat().st_size // 16, 4) and frame.points.dtype == np.float32
    deskewed = next(RawDrive(DRIVE, 2, deskew=True).select("5"))
    assert 0.01 < np.abs(deskewed.points[:, :3] - frame.points[:, :3]).max() < 5.0  # moved, but not far


@pytest.mark.parametrize(
    ("spec", "expected"),
    [("0-3", [0, 1, 2, 3]), ("5", [5]), ("1,4, 7", [1, 4, 7]), ("2-3,9", [2, 3, 9]), (None, None), (6, [6])],
)
def test_parse_frames(spec: object, expected: list[int] | None) -> None:
    assert parse_frames(spec) == expected  # type: ignore[arg-type]


@pytest.mark.parametrize("spec", ["3-1", "a", "", "-2"])
def test_parse_frames_rejects(spec: str) -> None:
    with pytest.raises(DataError, match="frames"):
        parse_frames(spec)


def test_missing_drive_and_camera_folders(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="drive folder not found"):
        RawDrive(tmp_path / "nope")
    with pytest.raises(DataError, match="image_01"):
        RawDrive(DRIVE, camera=1)


def test_python_api_gives_the_cli_depth(tmp_path: Path) -> None:
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.cli import main

    written = complete_kitti_raw(
        ClassicalCompleter(), DRIVE, tmp_path / "api", selection=RawDriveSelection(frames=[5]), log=lambda s: None
    )
    assert written == [tmp_path / "api" / "0000000005.png"]
    result = CliRunner().invoke(
        main, ["predict", "--method", "classical", "--kitti-raw", str(DRIVE), "--out", str(tmp_path / "cli")]
    )
    assert result.exit_code == 0, result.output
    api, cli = read_depth(written[0]), read_depth(tmp_path / "cli" / "0000000005.png")
    assert np.array_equal(api, cli) and np.count_nonzero(api) > 0.5 * api.size


FRAME_5 = RawDriveSelection(frames="5")


def _frame_5(**fields: object) -> RawDriveSelection:
    return RawDriveSelection(frames="5", **fields)  # type: ignore[arg-type]


class _Recorder:
    """A completer that records the semantic map it receives and returns the sparse depth plus weights."""

    needs_semantic, palette, device = True, "cityscapes", "cpu"

    def __call__(self, rgb, sparse, semantic=None):  # type: ignore[no-untyped-def]
        import torch

        from semattnet.inference import Completion
        from semattnet.models.outputs import DepthCompletionOutput

        self.semantic = semantic
        depth = torch.from_numpy(sparse + 1.0)[None, None]
        ones = torch.ones_like(depth)
        output = DepthCompletionOutput(depth, depth, depth, 0.2 * ones, 0.7 * ones, 0.1 * ones, depth, None, depth)
        return Completion(sparse + 1.0, output)


def test_semantic_folder_fallback_and_confidence(tmp_path: Path) -> None:
    from semattnet.data.io import write_image
    from semattnet.palette import UNKNOWN_COLOR

    rec = _Recorder()
    with pytest.warns(UserWarning, match="fallback"):
        complete_kitti_raw(rec, DRIVE, tmp_path / "a", selection=FRAME_5, log=lambda s: None)
    assert rec.semantic.shape == (375, 1242, 3) and (rec.semantic == np.array(UNKNOWN_COLOR, np.uint8)).all()
    sem_dir = tmp_path / "sem"
    sem_dir.mkdir()
    from semattnet.palette import ids_to_colors

    # a semantic map must be palette-coloured (a photo or a JPEG-resaved map is refused)
    palette_map = ids_to_colors((np.arange(375 * 1242).reshape(375, 1242) // 5000 % 19).astype(np.uint8))
    write_image(sem_dir / "0000000005.png", palette_map)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        complete_kitti_raw(rec, DRIVE, tmp_path / "b", selection=_frame_5(semantic=sem_dir), log=lambda s: None)
    assert np.array_equal(rec.semantic, palette_map)
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="0000000005.png"):
        complete_kitti_raw(
            rec, DRIVE, tmp_path / "c", selection=_frame_5(semantic=tmp_path / "empty"), log=lambda s: None
        )
    conf = fusion_confidence(rec(None, np.zeros((2, 2), np.float32)).output)
    assert conf is not None and np.allclose(conf, 0.7)
    assert fusion_confidence(None) is None


def test_segmenter_spec_colours_the_semantic_map(tmp_path: Path) -> None:
    from semattnet.palette import UNKNOWN_COLOR

    rec = _Recorder()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a segmenter is given: no fallback warning
        complete_kitti_raw(rec, DRIVE, tmp_path, selection=_frame_5(segmenter="unknown"), log=lambda s: None)
    assert rec.semantic.shape == (375, 1242, 3) and (rec.semantic == np.array(UNKNOWN_COLOR, np.uint8)).all()
    with pytest.raises(ValueError, match="not both"):
        _frame_5(segmenter="unknown", semantic=tmp_path / "sem")


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"frames": "3-1"}, "frames: not frame indices: '3-1'"),
        ({"frames": 2.5}, "frames: not frame indices: 2.5"),
        ({"camera": 4}, "camera: must be 0 to 3 .* got 4$"),
        ({"camera": "left"}, "camera: .* got 'left'$"),
        ({"camera": True}, "camera: .* got True$"),
        ({"deskew": "yes"}, "deskew: must be True or False, got 'yes'$"),
        ({"semantic": "sem", "segmenter": "unknown"}, "semantic: .*not both .*'sem'"),
    ],
)
def test_raw_drive_selection_refuses_bad_values_in_one_line(fields: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        RawDriveSelection(**fields)  # type: ignore[arg-type]
    assert "\n" not in str(caught.value)


def test_raw_drive_selection_takes_what_raw_drive_does() -> None:
    for camera in (2, 3, "02", "3"):
        assert RawDriveSelection(frames=[1, 4], camera=camera).camera == camera
    assert RawDriveSelection(frames="0-3,9", deskew=True).frames == "0-3,9"


def test_settings_reach_the_outputs(tmp_path: Path) -> None:
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.inference.options import OutputSpec
    from semattnet.inference.sinks import OutputSettings, PlyOptions

    out = tmp_path / "out"
    args = (ClassicalCompleter(), DRIVE, out)
    settings = OutputSettings(npy=True, max_depth=30.0, top_crop=100)
    complete_kitti_raw(*args, selection=FRAME_5, settings=settings, outputs=[PlyOptions(ply=True)], log=lambda s: None)
    assert {p.name for p in out.iterdir()} >= {"0000000005.png", "0000000005.npy", "0000000005.ply"}
    with pytest.raises(FileExistsError):
        complete_kitti_raw(*args, selection=FRAME_5, log=lambda s: None)
    complete_kitti_raw(*args, selection=FRAME_5, output=OutputSpec(overwrite=True), log=lambda s: None)
