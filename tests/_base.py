"""A small base class for tests of one function or module, in the style of kornia's BaseTester.

A subclass must define the five kinds of test every public piece of numerics gets:

* ``test_smoke``: it runs on typical input and returns the documented type;
* ``test_cardinality``: output shapes for several batch sizes and odd sizes;
* ``test_exception``: bad input raises the documented error with a message naming it;
* ``test_numerics``: values against hand computations or an independent slow reference;
* ``test_gradcheck``: ``torch.autograd.gradcheck`` in float64 at a tiny size (or a stated reason
  why the function is not differentiable, with a test of that).

It provides dtype-aware tolerances and a float64 gradcheck helper.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

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
    def assert_close(actual: torch.Tensor, expected: torch.Tensor, rtol: float | None = None,
                     atol: float | None = None) -> None:  # fmt: skip
        """``torch.testing.assert_close`` with this suite's tolerance for ``actual``'s dtype."""
        default_rtol, default_atol = TOLERANCES.get(actual.dtype, (1e-4, 1e-5))
        torch.testing.assert_close(
            actual, expected.to(actual.dtype), rtol=default_rtol if rtol is None else rtol,
            atol=default_atol if atol is None else atol,
        )  # fmt: skip

    @staticmethod
    def gradcheck(fn: Callable[..., torch.Tensor], *inputs: torch.Tensor, **kwargs: Any) -> bool:
        """``torch.autograd.gradcheck`` on float64 copies of ``inputs`` (those that require grad keep it)."""
        cast = [x.detach().double().requires_grad_(x.requires_grad) for x in inputs]
        return torch.autograd.gradcheck(fn, cast, **kwargs)
