"""What ``adapt --resume`` trusts of a run's state (``checkpoints/last.pt``): nothing it has not checked.

A state whose fields are not what a run writes (a text or negative step, a step past the run's end, an empty
optimiser state, a scheduler, scaler or generator of another shape) is refused with one line naming the file and the
field (:class:`~semattnet.weights.checkpoint.CheckpointError`). Options given with ``--resume`` that differ from the
run's (``--steps``, ``--lr``, ``--weights``, ...) are refused with one line naming the option and both values
(:class:`~semattnet._errors.InputError`): a resumed run continues the run it was, or does not start.
"""

from __future__ import annotations

import math
import os
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import TypedDict

import torch

from semattnet._errors import InputError
from semattnet.training.adapt.config import AdaptConfig
from semattnet.weights.checkpoint import CheckpointError, load_checkpoint

__all__ = ["FORMAT", "AdaptState", "Resumable", "read_state", "restore", "resumed_config"]

#: The ``format`` entry of an adaptation state.
FORMAT = "semattnet-adapt-v1"

#: Config fields whose command-line option is not ``--field-name``: the option, or the flag that turns them off.
_OPTIONS = {"losses": "--loss"}
_FLAGS = {"automask": "--no-automask", "freeze_bn": "--train-bn"}


class AdaptState(TypedDict):
    """What an exact resume restores from ``checkpoints/last.pt`` (besides the model's weights and config)."""

    adapt_config: dict[str, object]
    optimizer: dict[str, object]
    scheduler: dict[str, object]
    scaler: dict[str, object]
    rng: list[torch.Tensor]  # each rank's generator (one in a single process)
    step: int


Resumable = tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler, torch.amp.GradScaler]


def _damaged(path: Path, what: str) -> CheckpointError:
    return CheckpointError(
        f"{path}: damaged adaptation state: {what}; resume a state semattnet wrote, or start over with --overwrite"
    )


def _kind(value: object) -> str:
    return f"{type(value).__name__} {value!r}"[:80]


def read_state(path: Path) -> AdaptState:
    """An adaptation state (``checkpoints/last.pt``), verified (digest, format, every field's type); one line naming
    the file if not."""
    if not path.is_file():
        raise CheckpointError(f"{path}: nothing to resume from")
    extra = load_checkpoint(path).extra
    if extra.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a semattnet adapt state (no optimiser state to resume)")
    step = extra.get("step")
    if not isinstance(step, int) or isinstance(step, bool) or step < 0:
        raise _damaged(path, f"step is {_kind(step)}, not a whole number >= 0")
    for name in ("adapt_config", "optimizer", "scheduler", "scaler"):
        if not isinstance(extra.get(name), Mapping):
            raise _damaged(path, f"{name} is {_kind(extra.get(name))}, not a mapping")
    optimizer = extra["optimizer"]
    if not isinstance(optimizer.get("state"), Mapping) or not isinstance(optimizer.get("param_groups"), list):
        raise _damaged(path, "the optimiser state has no 'state' mapping and 'param_groups' list")
    if step > 0 and not optimizer["state"]:
        raise _damaged(path, f"the optimiser state is empty at step {step}")
    rng = extra.get("rng")  # a single tensor in the states of single-process runs before DDP
    rngs = [rng] if isinstance(rng, torch.Tensor) else rng
    fresh = torch.Generator().get_state()
    if not isinstance(rngs, list) or not rngs or not all(_like(fresh, r) for r in rngs):
        raise _damaged(path, "rng is not a list of the random generators' states")
    return AdaptState(
        adapt_config=dict(extra["adapt_config"]),
        optimizer=dict(optimizer),
        scheduler=dict(extra["scheduler"]),
        scaler=dict(extra["scaler"]),
        rng=list(rngs),
        step=step,
    )


def resumed_config(path: Path, state: AdaptState, given: AdaptConfig, asked: Collection[str] = ()) -> AdaptConfig:
    """The resumed run's configuration: the state's (the run may have moved: ``given.out``). ``asked``: the fields
    of ``given`` the caller chose (options on the command line); one that differs from the run's is refused.

    Raises:
        CheckpointError: the state's options are not an adaptation's, or its step lies past their end.
        InputError: an asked field differs from the run's, naming its option and both values.
    """
    try:
        saved = AdaptConfig.from_dict({**state["adapt_config"], "out": given.out})
    except (TypeError, ValueError) as exc:  # InputError is both
        raise _damaged(path, f"adapt_config: {' '.join(str(exc).split())[:200]}") from None
    if state["step"] > saved.steps:
        raise _damaged(path, f"step {state['step']} lies past the run's {saved.steps} steps")
    for name in asked:
        now, then = getattr(given, name), getattr(saved, name)
        if not (_same_weights(now, then) if name == "weights" else now == then):
            raise InputError(
                f"{_option(name, now)} differs from the run being resumed ({_option(name, then)}, in "
                f"{path}): resume without it, or start over with --overwrite"
            )
    return saved


def _option(name: str, value: object) -> str:
    """``name`` set to ``value`` as ``adapt``'s command line says it: ``--steps 20``, ``without --train-bn``."""
    if name in _FLAGS:
        return f"{'without' if value else 'with'} {_FLAGS[name]}"
    flag = _OPTIONS.get(name, "--" + name.replace("_", "-"))
    if isinstance(value, tuple):
        joint = "x" if name == "crop" else ".." if name == "hide" else ","
        return f"{flag} {joint.join(map(str, value))}"
    return f"{flag} {value}"


def _same_weights(now: str, then: str) -> bool:
    """The same weights: the same text, or two paths of one file or folder."""
    try:
        return now == then or os.path.samefile(now, then)
    except (OSError, ValueError):
        return False


def restore(path: Path, state: AdaptState, parts: Resumable, rng: torch.Generator, rank: int) -> None:
    """Load the state's optimiser, schedule, grad scaler and generator (of process ``rank``) into ``parts`` and
    ``rng``, each checked first against what this run's own would save."""
    optimizer, scheduler, scaler = parts
    _check_optimizer(path, optimizer, state["optimizer"])
    for name, part, saved in (("scheduler", scheduler, state["scheduler"]), ("scaler", scaler, state["scaler"])):
        fresh = part.state_dict()
        if fresh and (set(fresh) != set(saved) or not all(_like(fresh[k], saved[k]) for k in fresh)):
            wrong = sorted(
                k for k in set(fresh) | set(saved) if k not in fresh or k not in saved or not _like(fresh[k], saved[k])
            )
            raise _damaged(path, f"{name}: {', '.join(map(str, wrong[:3]))} not what this run's {name} saves")
    if state["scheduler"]["last_epoch"] != state["step"]:
        raise _damaged(path, f"scheduler: at step {state['scheduler']['last_epoch']}, the state at {state['step']}")
    if rank >= len(state["rng"]):
        raise _damaged(path, f"rng: {len(state['rng'])} generator(s), none for process {rank}")
    for name, load in (
        ("optimizer", lambda: optimizer.load_state_dict(state["optimizer"])),
        ("scheduler", lambda: scheduler.load_state_dict(state["scheduler"])),
        ("scaler", lambda: scaler.load_state_dict(state["scaler"])),
        ("rng", lambda: rng.set_state(state["rng"][rank])),
    ):
        try:
            load()
        except (ValueError, KeyError, TypeError, RuntimeError, IndexError, AttributeError) as exc:
            raise _damaged(path, f"{name}: {' '.join(str(exc).split())[:200]}") from None


def _check_optimizer(path: Path, optimizer: torch.optim.Optimizer, saved: Mapping[str, object]) -> None:
    """The saved optimiser state has this optimiser's groups (options of their types, the same parameters) and, per
    parameter, finite moments of its shape."""
    fresh = optimizer.state_dict()["param_groups"]
    groups = saved["param_groups"]
    assert isinstance(groups, list)  # read_state checked it
    if len(groups) != len(fresh) or not all(isinstance(g, Mapping) for g in groups):
        raise _damaged(path, f"optimizer: {len(groups)} parameter group(s), this run has {len(fresh)}")
    for i, (mine, theirs) in enumerate(zip(fresh, groups, strict=True)):
        if theirs.get("params") != mine["params"] or set(mine) - set(theirs):
            raise _damaged(path, f"optimizer: parameter group {i} is not this model's")
        wrong = [k for k in mine if k != "params" and not _like(mine[k], theirs[k])]
        if wrong:
            raise _damaged(path, f"optimizer: parameter group {i}: {wrong[0]} is {_kind(theirs[wrong[0]])}")
    params = [p for g in optimizer.param_groups for p in g["params"]]
    entries = saved["state"]
    assert isinstance(entries, Mapping)  # read_state checked it
    for key, entry in entries.items():
        if not isinstance(key, int) or not 0 <= key < len(params) or not isinstance(entry, Mapping):
            raise _damaged(path, f"optimizer: state {_kind(key)} names no parameter of the model")
        for name, value in entry.items():
            fits = isinstance(value, torch.Tensor) and (value.dim() == 0 or value.shape == params[key].shape)
            if not fits or not bool(torch.isfinite(value).all()):
                raise _damaged(path, f"optimizer: state {key}.{name} is not finite numbers of its parameter's shape")


def _like(fresh: object, saved: object) -> bool:
    """Whether ``saved`` has the structure of ``fresh``: finite numbers for numbers, as many items, the same keys,
    tensors of the same shape and dtype, the same type otherwise."""
    if isinstance(fresh, bool) or not isinstance(fresh, int | float | list | tuple | Mapping | torch.Tensor):
        return type(saved) is type(fresh)
    if isinstance(fresh, int | float):
        return isinstance(saved, int | float) and not isinstance(saved, bool) and math.isfinite(saved)
    if isinstance(fresh, torch.Tensor):
        return isinstance(saved, torch.Tensor) and saved.dtype == fresh.dtype and saved.shape == fresh.shape
    if isinstance(fresh, Mapping):
        return isinstance(saved, Mapping) and set(saved) == set(fresh) and all(_like(fresh[k], saved[k]) for k in fresh)
    return isinstance(saved, list | tuple) and len(saved) == len(fresh) and all(map(_like, fresh, saved))
