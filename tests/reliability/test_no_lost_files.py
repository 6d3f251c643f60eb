"""LOST cases: a command that writes never replaces one of its inputs (by path, symlink or hard link, even
with --overwrite) nor a special file, training never writes its run into its data, an archive never replaces a
file it did not write, a failed multi-file run replaces nothing."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import SemAttNetError
from semattnet._utils.outputs import OutputError, check_no_input_overlap
from semattnet.baselines import ClassicalCompleter
from semattnet.cli import main
from semattnet.data.archives import ArchiveConflictError, extract_zip
from tests.reliability._helpers import cli as _cli
from tests.reliability._helpers import one_line as _one_line

RIG = {
    "K": [[50, 0, 16], [0, 50, 12], [0, 0, 1]],
    "T_cam_lidar": [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
    "image_size": [32, 24],
}


def _invoke(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(res.exception, AssertionError)
    return res.exit_code, res.output


def _aliases(tmp_path: Path, target: Path) -> list[Path]:
    """The same file by another name: itself, a ``..`` detour, a symlink, a hard link."""
    (tmp_path / "sub").mkdir(exist_ok=True)
    sym, hard = tmp_path / "sym", tmp_path / "hard"
    for p in (sym, hard):
        p.unlink(missing_ok=True)
    sym.symlink_to(target)
    os.link(target, hard)
    return [target, tmp_path / "sub" / ".." / target.relative_to(tmp_path), sym, hard]


@pytest.fixture
def scan_and_rig(tmp_path: Path) -> tuple[Path, Path]:
    scan, rig = tmp_path / "scan.npy", tmp_path / "rig.json"
    np.save(scan, np.array([[5.0, 0.0, 0.0], [6.0, 0.5, 0.2]], np.float32))
    rig.write_text(json.dumps(RIG))
    return scan, rig


@pytest.mark.parametrize("which", ["scan", "rig"])
def test_project_never_writes_over_its_inputs(tmp_path: Path, scan_and_rig: tuple[Path, Path], which: str) -> None:
    scan, rig = scan_and_rig
    victim = scan if which == "scan" else rig
    before = victim.read_bytes()
    for out in _aliases(tmp_path, victim):
        code, output = _invoke("project", "--points", scan, "--rig", rig, "--out", out, "--overwrite")
        assert code == 1 and "would replace the input" in output and len(output.strip().splitlines()) == 1, output
        assert victim.read_bytes() == before
    code, output = _invoke("project", "--points", scan, "--rig", rig, "--out", tmp_path / "ok.png")
    assert code == 0, output


def test_convert_never_writes_over_its_source(tmp_path: Path) -> None:
    src = tmp_path / "model.pt"
    src.write_bytes(b"original checkpoint bytes")
    for dst in _aliases(tmp_path, src):
        code, output = _invoke("convert", src, dst, "--overwrite")
        assert code == 1 and "would replace the input" in output, output
        assert src.read_bytes() == b"original checkpoint bytes"
        code, output = _invoke("convert", "--weights", src, dst, "--overwrite")
        assert code == 1 and "would replace the input" in output, output
    assert src.read_bytes() == b"original checkpoint bytes"


def test_overlap_rule_by_inode_and_folder(tmp_path: Path) -> None:
    (tmp_path / "in").mkdir()
    a = tmp_path / "in" / "a.png"
    a.write_text("x")
    for alias in _aliases(tmp_path, a):
        with pytest.raises(OutputError, match="would replace the input"):
            check_no_input_overlap([a], out_files=[alias])
        with pytest.raises(OutputError):
            check_no_input_overlap([tmp_path / "in"], out_files=[alias] if alias.parent == a.parent else [a])
    linked = tmp_path / "linked_in"
    linked.symlink_to(tmp_path / "in", target_is_directory=True)
    with pytest.raises(OutputError, match="input folder"):
        check_no_input_overlap([tmp_path / "in"], out_dir=linked / "sub")
    check_no_input_overlap([a], out_files=[tmp_path / "new.png"])  # a new name is fine
    assert issubclass(OutputError, SemAttNetError)


def test_segment_into_its_image_folder_is_refused(tmp_path: Path) -> None:
    from semattnet.data.io import write_image
    from semattnet.segmentation.segmenter import Segmenter, segment_folder

    img = np.full((6, 8, 3), 7, np.uint8)
    write_image(tmp_path / "im" / "a.png", img)
    before = (tmp_path / "im" / "a.png").read_bytes()
    with pytest.raises(OutputError, match="a.png"):
        segment_folder(Segmenter(None, "unknown"), tmp_path / "im", tmp_path / "im", overwrite=True, progress=False)
    assert (tmp_path / "im" / "a.png").read_bytes() == before


def _zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


@pytest.mark.parametrize("kind", ["other-size", "folder", "symlink"])
def test_archives_never_replace_files_they_did_not_write(tmp_path: Path, kind: str) -> None:
    archive = _zip(tmp_path / "a.zip", {"d/one.txt": b"111", "d/two.txt": b"2222"})
    dest = tmp_path / "dest"
    mine = dest / "d" / "two.txt"
    mine.parent.mkdir(parents=True)
    if kind == "other-size":
        mine.write_text("user notes, not from the archive")
    elif kind == "folder":
        mine.mkdir()
    else:
        (tmp_path / "elsewhere.txt").write_text("keep")
        mine.symlink_to(tmp_path / "elsewhere.txt")
    with pytest.raises(ArchiveConflictError, match="two.txt") as err:
        extract_zip(archive, dest)
    assert "\n" not in str(err.value) and not (dest / "d" / "one.txt").exists()  # nothing unpacked
    if kind == "other-size":
        assert mine.read_text() == "user notes, not from the archive"
    assert not list(dest.rglob("*.part"))


def test_archive_rerun_skips_what_it_wrote(tmp_path: Path) -> None:
    archive = _zip(tmp_path / "a.zip", {"d/one.txt": b"111", "d/two.txt": b"2222"})
    assert extract_zip(archive, tmp_path / "dest") == (2, 0)
    assert extract_zip(archive, tmp_path / "dest") == (0, 2)


def test_predict_overwrite_keeps_whole_frames_when_a_late_frame_fails(tmp_path: Path) -> None:
    from semattnet.data.frames import Frame, IndexedSource
    from semattnet.data.io import read_depth
    from semattnet.inference.completer import Completion
    from semattnet.inference.pipeline import OutputSpec, check_frames
    from semattnet.inference.sinks import DepthPngSink

    class Source(IndexedSource):
        names = ("f0", "f1", "f2")

        def load(self, name: str) -> Frame:
            sparse = np.zeros((8, 12), np.float32)
            sparse[4, 6] = 5.0
            return Frame(name, np.zeros((8, 12, 3), np.uint8), sparse)

        def inputs(self) -> list[Path]:
            return []

    calls = []

    class Failing(ClassicalCompleter):
        def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
            calls.append(1)
            if len(calls) == 3:
                raise RuntimeError("the model failed on the last frame")
            return Completion(np.full(sparse.shape, 3.0, np.float32))

    completer = Failing()

    out = tmp_path / "out"
    out.mkdir()
    for n in Source.names:
        (out / f"{n}.png").write_bytes(b"previous " + n.encode())
    with pytest.raises(RuntimeError, match="last frame"):
        check_frames(Source(), [DepthPngSink()], out, OutputSpec(overwrite=True)).run(completer, log=lambda s: None)
    assert len(calls) == 3
    # the frames done before the error are replaced (each whole, as asked) and journaled; the failed one is not
    assert sorted(p.name for p in out.iterdir()) == ["f0.png", "f1.png", "f2.png", "frames.json"]
    assert (out / "f2.png").read_bytes() == b"previous f2"
    assert all(read_depth(out / f"{n}.png")[4, 6] == 3.0 for n in ("f0", "f1"))
    doc = json.loads((out / "frames.json").read_text())
    assert not doc["complete"] and [e["status"] for e in doc["frames"]] == ["done", "done", "pending"]


def test_sweeps_and_metrics_never_write_into_their_inputs(tmp_path: Path) -> None:
    from semattnet.evaluation.sparsity import sweep_model
    from semattnet.synthetic.tree import write_synthetic_kitti

    root = tmp_path / "kitti"
    write_synthetic_kitti(root, 2, (32, 64), eval_frames=2, workers=1)
    before = sorted(p for p in root.rglob("*"))
    with pytest.raises(OutputError, match="input folder"):
        sweep_model(root, "val_select", ["keep=1"], None, root / "sweep")
    assert sorted(p for p in root.rglob("*")) == before
    pred = next(root.rglob("*.png"))
    code, output = _invoke("metrics", pred.parent, pred.parent, "--json", pred, "--overwrite")
    assert code == 1 and "would replace the input" in output and pred.read_bytes()[:4] == b"\x89PNG", output


@pytest.mark.usefixtures("no_hang")
@pytest.mark.parametrize("kind", ["fifo", "hardlink-into-gt"])
def test_metrics_json_never_replaces_a_special_file_or_an_input(tmp_path: Path, kind: str) -> None:
    from semattnet.data.io import write_depth

    for d in ("pred", "gt"):
        write_depth(tmp_path / d / "a.png", np.full((4, 6), 5.0))
    json_path = tmp_path / "m.json"
    os.mkfifo(json_path) if kind == "fifo" else os.link(tmp_path / "gt" / "a.png", json_path)
    code, msg = _cli(tmp_path, "metrics", tmp_path / "pred", tmp_path / "gt", "--json", json_path, "--overwrite")
    assert code == 1 and "m.json" in msg, msg
    assert json_path.is_fifo() if kind == "fifo" else json_path.stat().st_nlink == 2


def test_visualize_never_replaces_a_hard_link_to_its_ground_truth(tmp_path: Path) -> None:
    from semattnet.data.io import write_depth

    for d in ("pred", "gt"):
        write_depth(tmp_path / d / "a.png", np.full((4, 6), 5.0))
    (tmp_path / "o").mkdir()
    os.link(tmp_path / "gt" / "a.png", tmp_path / "o" / "a_color.png")
    code, msg = _cli(
        tmp_path,
        "visualize",
        "--pred",
        tmp_path / "pred",
        "--gt",
        tmp_path / "gt",
        "--out",
        tmp_path / "o",
        "--overwrite",
    )
    assert code == 1 and "would replace the input" in msg and (tmp_path / "o" / "a_color.png").stat().st_nlink == 2


@pytest.mark.parametrize("where", ["data", "data/run", "semantic"])
def test_train_never_writes_its_run_into_the_data(tmp_path: Path, where: str) -> None:
    from semattnet.training.config import TrainConfig
    from semattnet.training.trainer import train

    for d in ("data", "semantic"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "keep.txt").write_text(d)
    cfg = TrainConfig(data=str(tmp_path / "data"), semantic_root=str(tmp_path / "semantic"), out=str(tmp_path / where))
    assert "input folder" in _one_line(lambda: train(cfg, overwrite=True))
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == ["keep.txt"]
