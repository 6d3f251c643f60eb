"""Parametrise every registry suite's tests that take ``entry`` over its ``entries()`` (tests/_base.py)."""

from __future__ import annotations

import pytest

from tests._base import RegistryTester


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    cls = metafunc.cls
    if "entry" in metafunc.fixturenames and cls is not None and issubclass(cls, RegistryTester):
        metafunc.parametrize("entry", [pytest.param(name, marks=cls.marks(name)) for name in cls.entries()])
