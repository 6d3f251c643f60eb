"""A small base class for tests of one function or module, in the style of kornia's BaseTester.

A subclass must define the five kinds of test every public piece of numerics gets:

* ``test_smoke``: it runs on typical input and returns the documented type;
* ``test_cardinality``: output shapes for several batch sizes and odd sizes;
* ``test_exception``: bad input raises the documented error with a message naming it;
* ``test_numerics``: values against hand computations or an independent slow reference;
* ``test_gradcheck``: ``torch.autograd.gradcheck`` in float64 at a tiny size (or a stated reason
  why the function is not differentiable, with a test of that).

It provides dtype-aware tolerances and a float64 gradcheck helper.

:class:`RegistryTester` is the same idea over a registry (models, released weights, engines, datasets,
sources, sinks): every registered entry runs through smoke, cardinality, exception and numerics tests, and an
entry registered without a fixture in its suite fails, so a new entry is tested by being registered.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Generic, TypeVar

import pytest
import torch

REQUIRED = ("test_smoke", "test_cardinality", "test_exception", "test_numerics", "test_gradcheck")

#: (rtol, atol) by dtype for assert_close.
TOLERANCES: dict[torch.dtype, tuple[float, float]] = {
    torch.float64: (1e-7, 1e-7),
    torch.float32: (1e-4, 1e-5),
    torch.bfloat16: (1.6e-2, 1e-2),
    torch.float16: (1e-3, 1e-3),
}


class BaseTester:
    """Subclass as ``class TestThing(BaseTester)``; pytest collects the subclass's tests."""

    required: ClassVar[tuple[str, ...]] = REQUIRED

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        missing = [name for name in cls.required if not callable(getattr(cls, name, None))]
        if missing:
            raise TypeError(f"{cls.__name__} must define {', '.join(missing)} (see tests/_base.py)")

    @staticmethod
    def assert_close(
        actual: torch.Tensor, expected: torch.Tensor, rtol: float | None = None, atol: float | None = None
    ) -> None:
        """``torch.testing.assert_close`` with this suite's tolerance for ``actual``'s dtype."""
        default_rtol, default_atol = TOLERANCES.get(actual.dtype, (1e-4, 1e-5))
        torch.testing.assert_close(
            actual,
            expected.to(actual.dtype),
            rtol=default_rtol if rtol is None else rtol,
            atol=default_atol if atol is None else atol,
        )

    @staticmethod
    def gradcheck(fn: Callable[..., torch.Tensor], *inputs: torch.Tensor, **kwargs: Any) -> bool:
        """``torch.autograd.gradcheck`` on float64 copies of ``inputs`` (those that require grad keep it)."""
        cast = [x.detach().double().requires_grad_(x.requires_grad) for x in inputs]
        return torch.autograd.gradcheck(fn, cast, **kwargs)


REGISTRY_REQUIRED = ("test_smoke", "test_cardinality", "test_exception", "test_numerics")
F = TypeVar("F")


class RegistryTester(Generic[F]):
    """A suite over one registry: subclass as ``class TestSinks(RegistryTester[SinkFixture])`` in
    ``tests/registry/`` and define

    * ``kind`` (what the entries are, for messages) and ``entries()`` (the registry's names, read at collection);
    * ``fixtures``: name -> the entry's fixture (how to build it on tiny inputs and what to expect);
    * ``test_smoke``, ``test_cardinality``, ``test_exception``, ``test_numerics``, each taking ``entry``: the
      conftest there parametrises every test that takes ``entry`` over ``entries()``.

    :meth:`fixture` fails a registered entry that has no fixture (naming the file to add it to), and
    ``test_fixtures_match_the_registry`` fails on a missing or a stale fixture."""

    required: ClassVar[tuple[str, ...]] = REGISTRY_REQUIRED
    kind: ClassVar[str]
    fixtures: ClassVar[Mapping[str, Any]]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        missing = [name for name in cls.required if not callable(getattr(cls, name, None))]
        missing += [name for name in ("kind", "fixtures") if not hasattr(cls, name)]
        if cls.entries is RegistryTester.entries:
            missing.append("entries")
        if missing:
            raise TypeError(f"{cls.__name__} must define {', '.join(missing)} (see tests/_base.py)")

    @classmethod
    def entries(cls) -> list[str]:
        """The registered names this suite runs over."""
        raise NotImplementedError

    @classmethod
    def marks(cls, name: str) -> tuple[pytest.MarkDecorator, ...]:
        """Marks of ``name``'s tests (e.g. ``pytest.mark.slow`` for a slow entry); none by default."""
        return ()

    def fixture(self, name: str) -> F:
        """``name``'s fixture; a registered entry without one fails here."""
        if name not in self.fixtures:
            where = type(self).__module__.replace(".", "/") + ".py"
            pytest.fail(f"{self.kind} {name!r} is registered but has no fixture: add one to {where}")
        fixture: F = self.fixtures[name]
        return fixture

    def test_fixtures_match_the_registry(self) -> None:
        entries, fixtures = set(self.entries()), set(self.fixtures)
        assert entries, f"no {self.kind} registered"
        assert not entries - fixtures, f"registered {self.kind}(s) without a fixture: {sorted(entries - fixtures)}"
        assert not fixtures - entries, f"fixtures of unregistered {self.kind}(s): {sorted(fixtures - entries)}"
