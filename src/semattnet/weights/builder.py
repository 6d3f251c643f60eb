"""The one model builder (as timm's ``build_model_with_cfg``): config from the weights, overrides, strict load.

Every way to get a model goes through :func:`build_model_with_weights`:
:func:`semattnet.weights.load_model`, :func:`semattnet.weights.from_pretrained` (names, files,
folders, URLs), :meth:`semattnet.weights.PretrainedWeights.build`, and ``torch.hub``
(``hubconf.py`` -> :func:`semattnet.weights.hub_model`). The steps:

1. **Config from the weights.** The config recorded beside them (a registry record, a folder's
   ``config.json``) or in the file (safetensors metadata, a ``config`` entry), else inferred from
   the tensor shapes (:func:`~semattnet.weights.checkpoint.config_from_state_dict`). A recorded
   config whose shapes contradict the tensors is a one-line :class:`WeightsMismatchError`.
2. **The caller's overrides.** A field that keeps the shapes (``refinement_mode``,
   ``iterations``); an override of a shape field (:data:`SHAPE_FIELDS`) to another value than the
   weights have, e.g. ``width=0.5`` on width-1 weights, is a one-line :class:`WeightsMismatchError`.
   ``arch`` (an entry point's model name) must be of the weights' model class (full model vs
   backbone, :func:`semattnet.models.registry.model_class`).
3. **A strict load** (:func:`~semattnet.weights.checkpoint.load_weights`; key renames such as
   the ``module.`` prefix happen in :func:`~semattnet.weights.checkpoint.filter_state_dict`),
   then the model is moved to ``device`` and put in eval mode.

Without weights (``weights=None``) only the config steps run and a freshly initialised model is
returned (training mode), as :func:`semattnet.build_model` does.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.models.config import SemAttNetConfig
from semattnet.models.registry import arch_for, build_model, model_config
from semattnet.weights.checkpoint import (
    Checkpoint,
    CheckpointError,
    StateDictMismatchError,
    config_from_state_dict,
    filter_state_dict,
    load_weights,
)

__all__ = ["SHAPE_FIELDS", "WeightsMismatchError", "build_model_with_weights", "weights_config"]

#: Config fields that decide parameter shapes: the weights fix them (``width`` by its channel count).
SHAPE_FIELDS = ("branches", "fusion", "refine", "width", "reduction", "kernel_sizes", "encoder")
#: The shape fields :func:`config_from_state_dict` reads from the tensors (``reduction`` is checked by the load).
_INFERRED = ("branches", "fusion", "refine", "width", "kernel_sizes")
#: Fields that change no shape but what the trained weights compute: a record and the file's own config must agree.
_TRAINED = ("affinity",)


class WeightsMismatchError(CheckpointError, StateDictMismatchError):
    """The weights do not fit what was asked: a contradicting override, record, config or entry point."""


def _value(cfg: SemAttNetConfig, name: str) -> object:
    """A shape field as the weights see it (``width``: the base channel count it gives)."""
    return round(32 * cfg.width) if name == "width" else getattr(cfg, name)


def _differences(a: SemAttNetConfig, b: SemAttNetConfig, fields: tuple[str, ...]) -> list[str]:
    return [f for f in fields if _value(a, f) != _value(b, f) and not (f == "kernel_sizes" and not a.refine)]


def weights_config(
    ckpt: Checkpoint, recorded: SemAttNetConfig | None = None, source: str | None = None
) -> SemAttNetConfig:
    """Step 1: the config of ``ckpt``: ``recorded`` (or the file's own), else inferred from the shapes.

    Raises:
        WeightsMismatchError: the recorded config's shapes contradict the tensors'.
        CheckpointError: nothing recorded and not a SemAttNet state dict.
    """
    given = recorded or ckpt.config
    try:
        inferred = config_from_state_dict(ckpt.state_dict, source or ckpt.path)
    except CheckpointError:
        if given is None:
            raise
        return given  # not inferable: the strict load decides
    if given is None:
        return inferred
    name = source or ckpt.path
    # the file's own config too when a record is used: a file that contradicts itself is refused either way
    for where, cfg in (("the recorded config", recorded), ("the config in the file's metadata", ckpt.config)):
        if cfg is not None:
            _refuse_differences(inferred, "in the tensors", cfg, _INFERRED, f"{name}: {where} contradicts the weights")
    if recorded is not None and ckpt.config is not None:
        _refuse_differences(
            ckpt.config, "in the file", recorded, _TRAINED, f"{name}: the recorded config contradicts the file's own"
        )
    return given


def _refuse_differences(
    truth: SemAttNetConfig, where: str, recorded: SemAttNetConfig, fields: tuple[str, ...], message: str
) -> None:
    """A :class:`WeightsMismatchError` ``message: <field> <recorded> recorded, <truth> <where>, ...`` when the two
    configs differ in ``fields``."""
    wrong = _differences(truth, recorded, fields)
    if wrong:
        shown = ", ".join(f"{f} {getattr(recorded, f)!r} recorded, {getattr(truth, f)!r} {where}" for f in wrong)
        raise WeightsMismatchError(f"{message}: {shown}")


def _apply_overrides(cfg: SemAttNetConfig, overrides: Mapping[str, object], source: str) -> SemAttNetConfig:
    """Step 2: ``cfg`` with ``overrides``; an override that changes a shape field is refused."""
    if not overrides:
        return cfg
    unknown = sorted(set(overrides) - set(cfg.to_dict()))
    if unknown:
        raise InputError(f"unknown config field(s) {unknown}; fields: {sorted(cfg.to_dict())}")
    new = cfg.replace(**overrides)
    wrong = _differences(cfg, new, SHAPE_FIELDS)
    if wrong:
        shown = ", ".join(f"{f}={overrides[f]!r} (the weights have {getattr(cfg, f)!r})" for f in wrong)
        raise WeightsMismatchError(
            f"{source}: override {shown} contradicts the weights; only fields that keep the shapes "
            "(e.g. refinement_mode, iterations) can change"
        )
    return new


def _check_arch(cfg: SemAttNetConfig, arch: str, source: str) -> None:
    """``arch`` (e.g. a torch.hub entry point) must build the weights' model class (full model vs backbone)."""
    if model_config(arch).refine != cfg.refine:
        kind = "full model" if cfg.refine else "backbone"
        raise WeightsMismatchError(
            f"{arch}: the weights {source} are for the {kind} ({arch_for(cfg)!r}); use the matching model name"
        )


def build_model_with_weights(
    weights: Checkpoint | Mapping[str, torch.Tensor] | None = None,
    *,
    config: SemAttNetConfig | None = None,
    arch: str | None = None,
    overrides: Mapping[str, object] | None = None,
    device: str | torch.device | None = None,
    source: str | None = None,
) -> nn.Module:
    """Build a model and load ``weights`` into it (strict), in eval mode; see the module docstring.

    Args:
        weights: a :class:`~semattnet.weights.Checkpoint` or a state dict; None: a fresh model.
        config: the config recorded beside the weights (registry record, ``config.json``); without
            weights, the config to build.
        arch: a registered model name (or alias). With weights, the model class they must be for;
            without, the base config when ``config`` is not given (default ``"semattnet"``).
        overrides: config fields to change (with weights: only those that keep the shapes).
        device: where to put the model (default: CPU, where the weights are read).
        source: how to name the weights in messages (default: the file's path).

    Raises:
        WeightsMismatchError: a record, override or ``arch`` contradicts the weights (one line).
        StateDictMismatchError: the strict load found missing, unexpected or mis-shaped keys.
        InputError: an unknown config field or model name.
    """
    overrides = dict(overrides or {})
    if weights is None:
        if config is not None and arch is not None:
            _check_arch(config, arch, source or "config")
        model = build_model(None if config is not None else arch, config=config, **overrides)
        return model.to(device) if device is not None else model
    if not isinstance(weights, Checkpoint):
        label = source or "state dict"
        weights = Checkpoint(path=Path(label), state_dict=filter_state_dict(weights), format="state_dict")
    label = source or str(weights.path)
    cfg = _apply_overrides(weights_config(weights, config, label), overrides, label)
    if arch is not None:
        _check_arch(cfg, arch, label)
    model = build_model(config=cfg)
    try:
        load_weights(model, weights)
    except StateDictMismatchError as exc:
        if config is not None or weights.config is None or isinstance(exc, WeightsMismatchError):
            raise
        raise _metadata_mismatch(label, cfg, str(exc)) from None
    return model.to(device if device is not None else "cpu").eval()


#: The fields that name a variant in a message about a file whose metadata names another variant than its tensors.
_VARIANT_FIELDS = ("encoder", "anchor", "refine", "width", "branches", "fusion", "kernel_sizes")


def _metadata_mismatch(label: str, cfg: SemAttNetConfig, found: str) -> WeightsMismatchError:
    """The one line for a file whose own config (its metadata) builds a model its tensors do not fit: the file
    contradicts itself, whatever variant it names."""
    named = ", ".join(f"{f} {getattr(cfg, f)!r}" for f in _VARIANT_FIELDS)
    detail = found.split(" does not fit the model: ", 1)[-1]
    return WeightsMismatchError(
        f"{label}: the config in the file's metadata ({named}) is not the model its tensors are of ({detail}); "
        "the file contradicts itself: not loaded"
    )
