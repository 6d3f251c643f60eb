"""``frames.json`` is verified, not trusted: a resume keeps a frame only when its inputs are unchanged and every
file it records is a regular file inside OUT with its recorded size and digest; it refuses a damaged journal in
one line naming the field, another weights folder or version, and never loses an earlier run's record. A lock
refuses a second run into a folder in use; output subfolders linked out of OUT and a user's ROS 1 bag are never
replaced."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from semattnet._errors import DataError
from semattnet._utils.lock import FolderBusyError
from semattnet._utils.outputs import Output, OutputError, check_outputs
from semattnet.baselines import ClassicalCompleter
from semattnet.data.io import write_depth, write_image
from semattnet.data.sources import FolderSource
from semattnet.inference.journal import ResumeError
from semattnet.inference.pipeline import OutputSpec, check_frames
from semattnet.inference.sinks import LatencySink, OutputSettings, default_sinks
from semattnet.inference.timing import StageTimes

N = 3


def _frames(root: Path) -> FolderSource:
    rng = np.random.default_rng(0)
    for i in range(N):
        write_image(root / "rgb" / f"f{i}.png", rng.integers(0, 255, (24, 32, 3), dtype=np.uint8))
        d = np.zeros((24, 32), np.float32)
        d[::2, ::3] = rng.uniform(2, 60, d[::2, ::3].shape)
        write_depth(root / "sparse" / f"f{i}.png", d)
    return FolderSource.pair(root / "rgb", root / "sparse")


def _run(source: FolderSource, out: Path, resume: bool = False, completer: Any = None) -> Any:
    sinks = [*default_sinks(), LatencySink(timer=StageTimes())]
    plan = check_frames(source, sinks, out, OutputSpec(resume=resume))
    return plan.run(completer or ClassicalCompleter(), log=lambda _: None)


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> tuple[FolderSource, Path]:
    """Three frames and a finished run of them (not to be changed: see :func:`done`)."""
    root = tmp_path_factory.mktemp("finished")
    source = _frames(root)
    _run(source, root / "out")
    return source, root / "out"


@pytest.fixture
def done(finished: tuple[FolderSource, Path], tmp_path: Path) -> tuple[FolderSource, Path]:
    """The frames of :func:`finished` and a copy of its run in ``tmp_path/out``."""
    shutil.copytree(finished[1], tmp_path / "out")
    return finished[0], tmp_path / "out"


def _edit(out: Path, change: Callable[[dict[str, Any]], None]) -> None:
    doc = json.loads((out / "frames.json").read_text())
    change(doc)
    (out / "frames.json").write_text(json.dumps(doc))


def _refusal(source: FolderSource, out: Path) -> str:
    with pytest.raises(ResumeError) as info:
        check_frames(source, default_sinks(), out, OutputSpec(resume=True))
    message = str(info.value)
    assert "\n" not in message and "frames.json" in message, message
    return message


def _kept(source: FolderSource, out: Path) -> set[str]:
    return check_frames(source, default_sinks(), out, OutputSpec(resume=True)).journal.kept


@pytest.mark.parametrize("rel", ["/etc/hostname", "../f0.png", "a/../../f0.png", ""])
def test_a_path_outside_out_is_a_damaged_field(done: tuple[FolderSource, Path], rel: str) -> None:
    source, out = done
    _edit(out, lambda d: d["frames"][0].update(files={rel: {"size": 1, "sha256": "0" * 64}}))
    assert "damaged field frames[0].files" in _refusal(source, out)


def test_only_whole_regular_files_inside_out_are_kept(done: tuple[FolderSource, Path], tmp_path: Path) -> None:
    source, out = done
    foreign = tmp_path / "foreign.png"
    foreign.write_bytes((out / "f0.png").read_bytes())  # same size, same bytes: still not ours
    (out / "f0.png").unlink()
    (out / "f0.png").symlink_to(foreign)
    data = bytearray((out / "f1_color.png").read_bytes())
    data[-20] ^= 0xFF  # same size, other content
    (out / "f1_color.png").write_bytes(bytes(data))
    _edit(out, lambda d: d["frames"][2].update(files={}))  # a done frame that names no file
    assert _kept(source, out) == set()
    _run(source, out, resume=True)
    assert not (out / "f0.png").is_symlink() and foreign.read_bytes() == (out / "f0.png").read_bytes()
    assert _kept(source, out) == {"f0", "f1", "f2"}


@pytest.mark.parametrize(
    ("field", "change"),
    [
        ("wall_s", lambda d: d.update(wall_s="abc")),
        ("wall_s", lambda d: d.update(wall_s=float("nan"))),
        ("wall_s", lambda d: d.update(wall_s=-5)),
        ("frames[1].stage_ms", lambda d: d["frames"][1].update(stage_ms=None)),
        ("frames[1].stage_ms['writing']", lambda d: d["frames"][1]["stage_ms"].update(writing="text")),
        ("frames[0]", lambda d: d["frames"].__setitem__(0, {})),
        ("frames[0].files['f0.png']", lambda d: d["frames"][0]["files"].update({"f0.png": 12})),
        ("run", lambda d: d.update(run="x")),
        ("run", lambda d: d.update(run={})),
        ("frames[2].inputs", lambda d: d["frames"][2].pop("inputs")),
    ],
)
def test_a_damaged_number_or_record_is_one_line_naming_the_field(
    done: tuple[FolderSource, Path], field: str, change: Callable[[dict[str, Any]], None]
) -> None:
    source, out = done
    _edit(out, change)
    message = _refusal(source, out)
    assert f"damaged field {field}:" in message and "--amp" not in message, message


def test_deeply_nested_json_is_one_line(done: tuple[FolderSource, Path]) -> None:
    source, out = done
    (out / "frames.json").write_text("[" * 100_000 + "]" * 100_000)
    assert "nested too deeply" in _refusal(source, out)


def test_a_journal_of_the_previous_format_is_refused(done: tuple[FolderSource, Path]) -> None:
    source, out = done
    _edit(out, lambda d: d.update(schema="semattnet.frames/1"))
    assert "cannot be verified" in _refusal(source, out)


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_a_journal_that_is_no_file_is_named_as_such(tmp_path: Path, kind: str) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    out.mkdir()
    if kind == "folder":
        (out / "frames.json").mkdir()
    else:
        os.mkfifo(out / "frames.json")
    message = _refusal(source, out)
    assert f"is a {'FIFO' if kind == 'fifo' else 'folder'}" in message and "no frames.json" not in message


def test_a_changed_version_is_not_called_an_option(done: tuple[FolderSource, Path]) -> None:
    source, out = done
    _edit(out, lambda d: d["run"].update(version="0.0.1"))
    message = _refusal(source, out)
    assert "written by semattnet 0.0.1" in message and "--version" not in message, message


def test_a_frame_whose_input_changed_is_done_again(tmp_path: Path) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)
    image = tmp_path / "rgb" / "f1.png"
    os.utime(image, ns=(image.stat().st_atime_ns, image.stat().st_mtime_ns + 10**9))  # edited since
    (tmp_path / "sparse" / "f2.png").write_bytes((tmp_path / "sparse" / "f0.png").read_bytes())  # replaced
    assert _kept(source, out) == {"f0"}


def test_a_weights_folder_is_recorded_by_digest(tmp_path: Path) -> None:
    from semattnet.cli.predict import _identity

    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "model.safetensors").write_bytes(b"one")
    first = _identity({"weights": str(tmp_path / "w")})
    (tmp_path / "w" / "model.safetensors").write_bytes(b"two")
    assert str(first["weights"]).startswith("sha256-tree:") and _identity({"weights": str(tmp_path / "w")}) != first


class _Fails(ClassicalCompleter):
    """A completer for which every frame is bad."""

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Any:
        raise DataError("no LiDAR point in the image")


def test_a_resume_that_completes_nothing_keeps_the_earlier_record(done: tuple[FolderSource, Path]) -> None:
    source, out = done
    before = (out / "frames.json").read_bytes()
    for p in out.glob("f*.png"):
        p.unlink()  # nothing kept: every frame is done again, and every one fails
    with pytest.raises(DataError, match="no frame could be completed"):
        _run(source, out, resume=True, completer=_Fails())
    assert (out / "frames.json").read_bytes() == before


def test_a_run_with_no_frame_done_leaves_nothing_and_blocks_nothing(tmp_path: Path) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    out.mkdir()
    with pytest.raises(DataError, match="no frame could be completed"):
        _run(source, out, completer=_Fails())
    assert list(out.iterdir()) == []  # no latency.json, no frames.json, no lock
    assert _run(source, out).counts["done"] == N  # the next run into it is not refused
    with pytest.raises(DataError, match="no frame could be completed"):
        _run(source, tmp_path / "new", completer=_Fails())
    assert not (tmp_path / "new").exists()  # nor a folder it made


def test_a_second_run_into_a_folder_in_use_is_refused(tmp_path: Path) -> None:
    import fcntl

    source, out = _frames(tmp_path), tmp_path / "out"
    out.mkdir()
    with open(out / ".semattnet.lock", "w") as held:  # another run holds the folder
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        held.write("4242\n")
        held.flush()
        with pytest.raises(FolderBusyError) as info:
            _run(source, out)
        assert "another semattnet run (process 4242)" in str(info.value) and "\n" not in str(info.value)
    assert {p.name for p in out.iterdir()} == {".semattnet.lock"}  # nothing written; its lock left alone
    _run(source, out)  # a lock file no process holds (a killed run's) is stale: taken over
    assert not (out / ".semattnet.lock").exists() and (out / "frames.json").is_file()


def test_an_output_subfolder_linked_out_of_out_is_refused_with_overwrite_too(tmp_path: Path) -> None:
    source, out, foreign = _frames(tmp_path), tmp_path / "out", tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "f0.png").write_bytes(b"a user's file")
    out.mkdir()
    (out / "uncertainty").symlink_to(foreign)
    with pytest.raises(OutputError, match=r"out/uncertainty is a symbolic link to .*foreign; remove the link"):
        check_frames(source, default_sinks(OutputSettings(uncertainty=True)), out, OutputSpec(overwrite=True))
    assert (foreign / "f0.png").read_bytes() == b"a user's file" and sorted(os.listdir(out)) == ["uncertainty"]


def test_overwrite_replaces_a_ros1_bag_by_our_mark_not_by_its_magic_bytes(tmp_path: Path) -> None:
    from semattnet.robotics.bags.writer import staged_bag

    theirs, ours = tmp_path / "theirs.bag", tmp_path / "ours.bag"
    theirs.write_bytes(b"#ROSBAG V2.0\nthe user's recording")
    with pytest.raises(OutputError, match="never a user's folder or file"):
        check_outputs([], [Output("--bag-out", theirs, "bag")], overwrite=True)
    with staged_bag(ours) as tmp:
        tmp.write_bytes(b"#ROSBAG V2.0\nours")
    check_outputs([], [Output("--bag-out", ours, "bag")], overwrite=True)  # ours: replaceable
    ours.write_bytes(b"#ROSBAG V2.0\nrecorded over ours by the user")
    with pytest.raises(OutputError, match="never a user's folder or file"):
        check_outputs([], [Output("--bag-out", ours, "bag")], overwrite=True)


def test_the_cli_says_a_damaged_journal_in_one_line(done: tuple[FolderSource, Path]) -> None:
    from click.testing import CliRunner

    from semattnet.cli import main

    source, out = done
    _edit(out, lambda d: d.update(wall_s="abc"))
    rgb, sparse = source.given
    res = CliRunner().invoke(
        main, ["predict", "--method", "classical", "--rgb", str(rgb), "--sparse", str(sparse), "--resume", str(out)]
    )
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert res.exit_code == 1 and len(errors) == 1, res.output
    assert "frames.json: damaged field wall_s: 'abc'" in errors[0], res.output


def test_a_kept_depth_is_read_back_only_while_it_is_the_recorded_file(
    done: tuple[FolderSource, Path], tmp_path: Path
) -> None:
    source, out = done
    plan = check_frames(source, default_sinks(), out, OutputSpec(resume=True))
    plan.release()
    assert plan.journal.stored("f0", "f0.png") == out / "f0.png"
    (tmp_path / "foreign.png").write_bytes((out / "f0.png").read_bytes())
    (out / "f0.png").unlink()
    (out / "f0.png").symlink_to(tmp_path / "foreign.png")  # swapped after the check: never replayed into a bag
    with pytest.raises(ResumeError, match="f0.png: changed or replaced while the resume ran"):
        plan.journal.stored("f0", "f0.png")


def test_a_resume_keeps_the_record_of_frames_whose_input_is_gone(tmp_path: Path) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)
    for role in ("rgb", "sparse"):
        (tmp_path / role / "f2.png").unlink()
    fewer = FolderSource.pair(tmp_path / "rgb", tmp_path / "sparse")
    assert _run(fewer, out, resume=True).counts["done"] == N - 1
    doc = json.loads((out / "frames.json").read_text())
    assert [e["name"] for e in doc["frames"]] == ["f0", "f1"] and [e["name"] for e in doc["earlier"]] == ["f2"]
    assert (out / "f2.png").is_file()  # its files stay, and so does their record
