"""``evaluate_split``'s typed inputs: a :class:`~semattnet.inference.contract.CompleterFactory` is built only when
asked for (never told from a completer by its signature), and a scored run refuses a real-time replay."""

from __future__ import annotations

from pathlib import Path

import pytest

from semattnet._errors import InputError
from semattnet.baselines import ClassicalCompleter
from semattnet.evaluation import EvalSplit, evaluate_split
from semattnet.evaluation.evaluate import resolve_completer
from semattnet.inference import CompleterFactory, RunOptions


def test_a_factory_is_built_and_a_completer_is_kept() -> None:
    completer = ClassicalCompleter()
    built: list[ClassicalCompleter] = []
    factory = CompleterFactory(lambda: built.append(completer) or completer)
    assert built == []  # nothing is built until it is resolved
    assert resolve_completer(factory) is completer and built == [completer]
    assert resolve_completer(completer) is completer
    with pytest.raises(InputError, match=r"submit: 42 is neither a completer .* nor a CompleterFactory"):
        resolve_completer(42, "submit")  # type: ignore[arg-type]


def test_a_scored_run_refuses_a_real_time_replay(tmp_path: Path) -> None:
    never = CompleterFactory(lambda: pytest.fail("built before the options were checked"))
    with pytest.raises(InputError, match="real-time replay"):
        evaluate_split(never, EvalSplit(tmp_path), options=RunOptions(realtime=1.0))
