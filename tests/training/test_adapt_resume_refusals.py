"""``adapt --resume`` continues the run it was or does not start: options that differ from the run's are refused
naming the option and both values, and a doctored state (a text or negative step, an empty optimiser state, a garbage
scheduler, scaler, generator or options) is one ``CheckpointError`` line naming the file, never a traceback; nothing
in the run folder is written."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch

from semattnet._errors import InputError
from semattnet.training.adapt import LOG, STATE, adapt
from semattnet.weights.checkpoint import CheckpointError
from semattnet.weights.gate import DIGEST_KEY, tensor_digest
from tests.training._adapt_runs import digests, rt_checkpoint
from tests.training.test_adapt import _cfg, _Frames, _quiet

pytestmark = pytest.mark.filterwarnings("ignore:no semantic maps given")


@pytest.fixture(scope="module")
def rt_weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rt_checkpoint(tmp_path_factory.mktemp("rt-weights") / "rt.safetensors")


@pytest.fixture(scope="module")
def finished(rt_weights: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run of 2 steps (lr 1e-4, crop 32x64), not to be changed: see :func:`run`."""
    out = tmp_path_factory.mktemp("finished") / "run"
    adapt(_cfg(rt_weights, out, save_every=1), _Frames(), log=_quiet)
    return out


@pytest.fixture
def run(finished: Path, tmp_path: Path) -> Path:
    """A copy of :func:`finished` in ``tmp_path/run``."""
    shutil.copytree(finished, tmp_path / "run")
    return tmp_path / "run"


@pytest.mark.parametrize(
    ("field", "value", "said"),
    [
        ("steps", 5, "--steps 5 differs from the run being resumed (--steps 2, in "),
        ("lr", 1e-3, "--lr 0.001 differs from the run being resumed (--lr 0.0001, in "),
        ("crop", (32, 32), "--crop 32x32 differs from the run being resumed (--crop 32x64, in "),
        ("freeze_bn", False, "with --train-bn differs from the run being resumed (without --train-bn, in "),
    ],
)
def test_a_resume_with_other_options_than_the_run_is_refused_naming_both_values(
    run: Path, rt_weights: Path, field: str, value: object, said: str
) -> None:
    before = digests(run)
    with pytest.raises(InputError) as info:
        adapt(_cfg(rt_weights, run, **{field: value}), _Frames(), resume=True, asked=[field], log=_quiet)
    message = str(info.value)
    assert said in message and str(run / STATE) in message and "\n" not in message, message
    assert digests(run) == before


def test_a_resume_with_other_weights_is_refused_and_the_same_weights_by_another_path_accepted(
    run: Path, rt_weights: Path, tmp_path: Path
) -> None:
    other = tmp_path / "other.safetensors"
    shutil.copy(rt_weights, other)
    with pytest.raises(
        InputError, match=f"--weights {other} differs from the run being resumed \\(--weights {rt_weights}"
    ):
        adapt(_cfg(other, run), _Frames(), resume=True, asked=["weights"], log=_quiet)
    linked = tmp_path / "linked.safetensors"
    linked.symlink_to(rt_weights)
    result = adapt(_cfg(linked, run), _Frames(), resume=True, asked=["weights", "steps", "lr"], log=_quiet)
    assert result.step == 2


def _doctor(path: Path, change: Callable[[dict[str, Any]], None]) -> None:
    """Change the state at ``path`` as someone with ``torch`` would: the digest of its tensors computed again."""
    state = torch.load(path, weights_only=True)
    change(state)
    state[DIGEST_KEY] = tensor_digest(state)
    torch.save(state, path)


def _set(key: str, value: object) -> Callable[[dict[str, Any]], None]:
    return lambda state: state.__setitem__(key, value)


def _inside(key: str, sub: str, value: object) -> Callable[[dict[str, Any]], None]:
    return lambda state: state[key].__setitem__(sub, value)


def _moment(state: dict[str, Any]) -> None:
    state["optimizer"]["state"][0]["exp_avg"] = torch.zeros(7)


def _group_lr(state: dict[str, Any]) -> None:
    state["optimizer"]["param_groups"][0]["lr"] = "fast"


DOCTORED = {
    "a text step": (_set("step", "two"), "step is str 'two', not a whole number"),
    "a step in digits as text": (_set("step", "1"), "step is str '1', not a whole number"),
    "a negative step": (_set("step", -1), "step is int -1, not a whole number >= 0"),
    "a step past the run's end": (_set("step", 99), "step 99 lies past the run's 2 steps"),
    "an empty optimiser": (_set("optimizer", {}), "the optimiser state has no 'state'"),
    "an empty optimiser state": (_inside("optimizer", "state", {}), "the optimiser state is empty at step 2"),
    "a moment of another shape": (_moment, "optimizer: state 0.exp_avg is not finite numbers"),
    "a text learning rate": (_group_lr, "optimizer: parameter group 0: lr is str 'fast'"),
    "a garbage scheduler": (_set("scheduler", "garbage"), "scheduler is str 'garbage', not a mapping"),
    "a scheduler of text": (_inside("scheduler", "last_epoch", "x"), "scheduler: last_epoch not what"),
    "a scheduler at another step": (_inside("scheduler", "last_epoch", 1), "scheduler: at step 1, the state at 2"),
    "a garbage scaler": (_set("scaler", [1, 2]), "scaler is list [1, 2], not a mapping"),
    "a garbage generator": (_set("rng", [torch.zeros(3, dtype=torch.uint8)]), "rng is not a list of the random"),
    "garbage options": (_inside("adapt_config", "steps", "many"), "adapt_config: steps must be a whole number"),
    "options that are no mapping": (_set("adapt_config", "x"), "adapt_config is str 'x', not a mapping"),
}


@pytest.mark.parametrize("case", list(DOCTORED))
def test_a_doctored_state_is_one_line_naming_the_file(run: Path, rt_weights: Path, case: str) -> None:
    change, said = DOCTORED[case]
    _doctor(run / STATE, change)
    before = digests(run)
    with pytest.raises(CheckpointError) as info:
        adapt(_cfg(rt_weights, run), _Frames(), resume=True, log=_quiet)
    message = str(info.value)
    assert message.startswith(f"{run / STATE}: damaged adaptation state: ") and "\n" not in message, message
    assert said in message, message
    assert digests(run) == before


def test_a_damaged_log_is_rebuilt_from_the_state_not_a_traceback(run: Path, rt_weights: Path) -> None:
    (run / LOG).write_text('{"steps": [{"loss": 1}, "text", {"step": "1"}, {"step": 1, "loss": 0.5}], "metrics": 3}')
    result = adapt(_cfg(rt_weights, run), _Frames(), resume=True, log=_quiet)
    assert result.step == 2
