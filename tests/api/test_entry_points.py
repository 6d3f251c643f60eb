"""The library's entry points stay narrow (issue 44): the frame loop and the split's evaluation take typed
option objects (:class:`~semattnet.inference.options.OutputSpec`, :class:`~semattnet.inference.options.RunOptions`,
:class:`~semattnet.evaluation.evaluate.EvalSplit`, ...) rather than a keyword per option, and nothing in ``src/``
tells what a callable is by reading its signature (a lazy completer says so:
:class:`~semattnet.inference.contract.CompleterFactory`)."""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable
from pathlib import Path

import pytest

import semattnet
from semattnet.evaluation import evaluate_split
from semattnet.inference import check_frames, complete_frames

SRC = Path(semattnet.__file__).resolve().parent
MAX_PARAMETERS = 6
SIGNATURE_READ = re.compile(r"\binspect\.signature\b|\bfrom inspect import\b[^\n]*\bsignature\b|\.__code__\.co_")


@pytest.mark.parametrize("fn", [complete_frames, check_frames, evaluate_split], ids=lambda f: f.__name__)
def test_entry_points_take_at_most_six_parameters(fn: Callable[..., object]) -> None:
    assert len(inspect.signature(fn).parameters) <= MAX_PARAMETERS


def test_nothing_in_src_reads_a_signature() -> None:
    found = [
        f"{p.relative_to(SRC)}:{i}"
        for p in sorted(SRC.rglob("*.py"))
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if SIGNATURE_READ.search(line)
    ]
    assert found == []


def test_the_signature_check_sees_each_way_of_reading_one() -> None:
    assert SIGNATURE_READ.search("params = inspect.signature(f).parameters")
    assert SIGNATURE_READ.search("from inspect import getdoc, signature")
    assert SIGNATURE_READ.search("n = f.__code__.co_argcount")
    assert not SIGNATURE_READ.search("a signature of the run (its identity)")
