"""A transform tree bounded in frames: a peer naming thousands of frames is refused in one line, the tree kept, and
an error lists a few frames, not all of them."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rosbags")

from semattnet._errors import DataError
from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.bags.encode import tf_message
from semattnet.robotics.bags.tf import MAX_FRAMES, NoTransformError, TransformTree

TS = rosbags_typestore(False)


def _star(n: int, root: str = "base") -> object:
    return tf_message(TS, [(root, f"f{i}", np.eye(4)) for i in range(n)], 0)


def test_a_message_naming_more_frames_than_a_tree_holds_is_refused_and_the_tree_kept() -> None:
    tree = TransformTree("/tf_static")
    tree.add_message(_star(3))
    with pytest.raises(DataError) as err:
        tree.add_message(_star(2485, root="hostile"), "/tf_static message 1")
    text = str(err.value)
    assert text.startswith("/tf_static message 1: 2485 transform(s)") and f"beyond the {MAX_FRAMES} frames" in text
    assert "\n" not in text and len(text) < 300
    assert tree.frames == ["base", "f0", "f1", "f2"]  # nothing of the refused message added


def test_a_full_tree_still_answers_quickly_and_its_error_lists_a_few_frames() -> None:
    tree = TransformTree("/tf_static")
    tree.add_message(_star(MAX_FRAMES - 1))  # the most a tree holds: a root and its children
    assert len(tree.frames) == MAX_FRAMES
    with pytest.raises(NoTransformError) as err:
        tree.lookup("camera", "f7")
    assert "and 492 more" in str(err.value) and len(str(err.value)) < 400
    np.testing.assert_array_equal(tree.lookup("f3", "f7"), np.eye(4))
