"""Map the authors' flat encoder keys onto a stand-alone encoder module (as timm's ``checkpoint_filter_fn``).

The paper's backbone keeps the authors' names (``rgb_conv_init``, ``rgb_encoder_layer{1..10}``,
``segment_conv_init``, ``segment_encoder_layer{i}``, ``depth_conv_init``, ``depth_layer{i}``) so that
their checkpoints load with ``strict=True``. A model built from the generic encoders of
:mod:`semattnet.models.encoders` names the same layers ``stem`` and ``layer{i}`` of a
:class:`~semattnet.models.encoders.ResNetEncoder`; :func:`authors_encoder_filter` gives a branch's
encoder state dict from an authors' (backbone or full-model) state dict.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import torch

from semattnet._errors import InputError
from semattnet.weights.checkpoint import filter_state_dict

__all__ = ["AUTHORS_ENCODER_NAMES", "authors_encoder_filter"]

#: branch -> (the authors' stem name, their block prefix).
AUTHORS_ENCODER_NAMES: dict[str, tuple[str, str]] = {
    "rgb": ("rgb_conv_init", "rgb_encoder_layer"),
    "segment": ("segment_conv_init", "segment_encoder_layer"),
    "depth": ("depth_conv_init", "depth_layer"),
}


def authors_encoder_filter(state_dict: Mapping[str, torch.Tensor], branch: str) -> dict[str, torch.Tensor]:
    """The ``branch`` encoder's entries of an authors' state dict, renamed for a :class:`ResNetEncoder`.

    ``rgb_conv_init.0.weight`` -> ``stem.0.weight``, ``rgb_encoder_layer3.conv1.weight`` ->
    ``layer3.conv1.weight``; a ``backbone.`` (full model) or ``module.`` prefix is accepted.

    Raises:
        InputError: an unknown branch, or a state dict without that branch's encoder.
    """
    if branch not in AUTHORS_ENCODER_NAMES:
        raise InputError(f"branch must be one of {tuple(AUTHORS_ENCODER_NAMES)}, got {branch!r}")
    stem, prefix = AUTHORS_ENCODER_NAMES[branch]
    pattern = re.compile(rf"^(?:backbone\.)?(?:{stem}(?P<stem>\..+)|{prefix}(?P<index>\d+)(?P<rest>\..+))$")
    out: dict[str, torch.Tensor] = {}
    for key, value in filter_state_dict(state_dict).items():
        m = pattern.match(key)
        if m is None:
            continue
        out["stem" + m["stem"] if m["stem"] else f"layer{m['index']}{m['rest']}"] = value
    if not any(k.startswith("stem.") for k in out):
        raise InputError(f"state dict has no {branch} encoder (no {stem}.* keys)")
    return out
