"""``write_submission``: the KITTI test split through the one frame loop into a checked stage, then the zip."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import InputError
from semattnet.baselines.classical import ClassicalCompleter
from semattnet.data.io import encode_depth, read_depth
from semattnet.data.sources import KittiSplitSource
from semattnet.evaluation.submission import SubmissionError, write_submission
from semattnet.inference.completer import Completion
from semattnet.inference.contract import CompleterFactory
from semattnet.inference.sinks import predict_frame
from semattnet.synthetic.tree import write_synthetic_kitti


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("submission") / "kitti"
    write_synthetic_kitti(root, 1, (32, 64), seed=4, eval_frames=2, workers=1)
    return root


class Never:
    """A completer factory that must not be called (every check comes first)."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self) -> ClassicalCompleter:
        self.calls += 1
        raise AssertionError("the completer was made before the checks")


def test_the_test_split_through_the_loop(tree: Path, tmp_path: Path) -> None:
    """Every test frame's prediction, named as its sparse file, as the loop stores it; nothing else anywhere."""
    out = tmp_path / "sub"
    zip_path = write_submission(CompleterFactory(ClassicalCompleter), tree, out, expected_frames=2)
    source = KittiSplitSource(tree, "test")
    names = sorted(source.by_name[n].sparse.name for n in source.names)
    assert sorted(p.name for p in out.iterdir()) == names and len(names) == 2  # no journal, no stage
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub", "sub.zip"]
    with zipfile.ZipFile(zip_path) as zf:
        assert sorted(zf.namelist()) == names
    for name in source.names:
        frame = source.load(name)
        png = encode_depth(predict_frame(frame, ClassicalCompleter()(frame.rgb, frame.sparse)).stored)
        assert np.array_equal(encode_depth(read_depth(out / source.by_name[name].sparse.name)), png)


def test_checks_come_before_the_completer(tree: Path, tmp_path: Path) -> None:
    never = Never()
    with pytest.raises(SubmissionError, match="KITTI expects 1000"):
        write_submission(CompleterFactory(never), tree, tmp_path / "a")
    write_submission(ClassicalCompleter(), tree, tmp_path / "b", expected_frames=None)
    with pytest.raises(FileExistsError, match="--overwrite"):
        write_submission(CompleterFactory(never), tree, tmp_path / "b", expected_frames=None)
    (tmp_path / "b" / "notes.txt").write_text("mine")
    with pytest.raises(SubmissionError, match="notes.txt"):
        write_submission(CompleterFactory(never), tree, tmp_path / "b", expected_frames=None, overwrite=True)
    assert never.calls == 0 and (tmp_path / "b" / "notes.txt").read_text() == "mine"
    with pytest.raises(InputError, match="submit: 42 is neither a completer .* nor a CompleterFactory"):
        write_submission(42, tree, tmp_path / "c", expected_frames=None)  # type: ignore[arg-type]


def test_the_read_back_check_and_the_holes_warning(tree: Path, tmp_path: Path) -> None:
    """A prediction of the wrong size fails the read-back check (nothing written); holes are warned."""

    class Cropped(ClassicalCompleter):
        def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
            return Completion(np.full((sparse.shape[0] - 1, sparse.shape[1]), 5.0, np.float32))

    with pytest.raises(SubmissionError, match="read-back check"):
        write_submission(Cropped(), tree, tmp_path / "a", expected_frames=None)
    assert not list(tmp_path.iterdir())  # no folder, no zip, no stage

    class Holed(ClassicalCompleter):
        def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
            depth = np.full(sparse.shape, 5.0, np.float32)
            depth[0, :3] = 0.0
            return Completion(depth)

    with pytest.warns(UserWarning, match=r"submission: 6 hole\(s\) .* in 2 file\(s\)"):
        write_submission(Holed(), tree, tmp_path / "b", expected_frames=None)
    assert all((read_depth(p) == 0).sum() == 3 for p in (tmp_path / "b").iterdir())
