"""The synthetic scenes' old paths (``semattnet.data.synthetic`` and its modules, four names of ``semattnet.data``):
the same objects as :mod:`semattnet.synthetic`'s, each with a ``DeprecationWarning`` naming the new home, until 0.3."""

from __future__ import annotations

import importlib
import sys

import pytest

import semattnet.data
import semattnet.synthetic
from semattnet import _moved
from semattnet.synthetic import drive, world


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("semattnet.data.synthetic", semattnet.synthetic),
        ("semattnet.data.synthetic.drive", drive),
        ("semattnet.data.synthetic.world", world),
    ],
)
def test_an_old_module_path_warns_and_holds_the_new_modules_names(
    old: str, new: object, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in [n for n in sys.modules if n.startswith("semattnet.data.synthetic")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.warns(DeprecationWarning, match=rf"{old} is deprecated .* 0\.3: use {new.__name__}$"):  # type: ignore[attr-defined]
        module = importlib.import_module(old)
    assert all(getattr(module, name) is getattr(new, name) for name in new.__all__)  # type: ignore[attr-defined]


def test_the_old_names_of_semattnet_data_warn_and_are_the_new_objects() -> None:
    for name in _moved.MOVED_NAMES:
        with pytest.warns(DeprecationWarning, match=rf"semattnet\.data\.{name} is deprecated"):
            assert getattr(semattnet.data, name) is getattr(semattnet.synthetic, name)
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        semattnet.data.nothing_here  # noqa: B018


def test_a_path_that_never_existed_is_still_not_found() -> None:
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("semattnet.data.synthetic.nothing_here")
