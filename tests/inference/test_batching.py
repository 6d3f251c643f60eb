"""``batch_size`` of the one frame loop: frames of one size in one engine call, the numbers of one call per frame
(up to float rounding), each frame's input checks kept."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import semattnet
from semattnet._errors import InputError
from semattnet.evaluation import EvalSplit, evaluate_split
from semattnet.inference import DepthCompleter, RunOptions
from semattnet.inference.backends import EngineSpec
from semattnet.inference.batching import groups
from semattnet.synthetic.tree import write_synthetic_kitti


def test_groups_keep_order_size_and_faults() -> None:
    from semattnet.data.frames import Frame

    def frame(name: str, h: int) -> Frame:
        return Frame(name, np.zeros((h, 4, 3), np.uint8), np.zeros((h, 4), np.float32))

    items = [frame("a", 2), frame("b", 2), frame("c", 2), "fault", frame("d", 2), frame("e", 3)]
    got = [[getattr(i, "name", i) for i in g] for g in groups(iter(items), 2)]
    assert got == [["a", "b"], ["c"], ["fault"], ["d"], ["e"]]


def test_evaluate_batched_equals_one_per_call(tmp_path: Path) -> None:
    write_synthetic_kitti(tmp_path / "t", frames=1, size=(64, 128), seed=4, eval_frames=3, workers=1)
    model = semattnet.build_model("semattnet", width=0.125)
    model.backbone.init_depth_heads()
    completer = DepthCompleter(model, EngineSpec(device="cpu"))
    one = evaluate_split(completer, EvalSplit(tmp_path / "t")).result
    three = evaluate_split(completer, EvalSplit(tmp_path / "t"), options=RunOptions(batch_size=3)).result
    assert one.keys() == three.keys() and one["images"] == three["images"] == 3
    for k, v in one.items():
        assert three[k] == pytest.approx(v, rel=1e-4, abs=1e-6), k
    rgb = np.zeros((64, 128, 3), np.uint8)
    sparse = np.zeros((64, 128), np.float32)
    sparse[10, 10] = 5.0
    with pytest.raises(InputError, match="one size"):
        completer.complete_batch([(rgb, sparse, rgb), (rgb[:32], sparse[:32], rgb[:32])])
    with pytest.raises(InputError, match="sparse"):  # each frame's checks apply in a batch too
        completer.complete_batch([(rgb, sparse, rgb), (rgb, np.full((64, 128), -1.0, np.float32), rgb)])
