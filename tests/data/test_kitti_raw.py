"""The old home of KITTI raw drives, ``semattnet.data.kitti_raw``: a deprecated alias of
:mod:`semattnet.data.kitti.raw` until 0.3 (the own-camera guide showed it to users)."""

from __future__ import annotations

import importlib
import sys

import pytest

from semattnet.data.kitti import raw


def test_the_old_path_warns_and_gives_the_same_objects(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "semattnet.data.kitti_raw", raising=False)
    with pytest.warns(DeprecationWarning, match=r"semattnet\.data\.kitti\.raw.*|0\.3"):
        old = importlib.import_module("semattnet.data.kitti_raw")
    assert old.RawDrive is raw.RawDrive and old.parse_frames is raw.parse_frames
    assert set(old.__all__) == set(raw.__all__)
