"""Model registry: ``build_model(name, **overrides)`` and the variants of the paper.

``semattnet`` and ``semattnet_backbone`` are the released models (authors' parameter names);
``table2_a`` ... ``table2_g`` are the ablations of the paper's Table 2.
"""

from __future__ import annotations

from typing import Any

from torch import nn

from semattnet.models.backbone import SemAttNetBackbone
from semattnet.models.config import SemAttNetConfig
from semattnet.models.semattnet import SemAttNet

__all__ = ["MODELS", "build_model", "describe_models", "list_models"]

#: name -> (description, config). Overrides passed to build_model replace fields.
MODELS: dict[str, tuple[str, SemAttNetConfig]] = {
    "semattnet": ("Full SemAttNet: three branches, SAMMAFB, CSPN++ refinement (Table 2 g)", SemAttNetConfig()),
    "semattnet_backbone": (
        "Three-branch backbone with SAMMAFB, no refinement (Table 2 f)",
        SemAttNetConfig(refine=False),
    ),
    "table2_a": ("CG + DG, fusion by addition", SemAttNetConfig(branches=2, fusion="add", refine=False)),
    "table2_b": ("CG + DG, fusion by concatenation", SemAttNetConfig(branches=2, fusion="concat", refine=False)),
    "table2_c": ("CG + DG, concatenation, CSPN++ refinement", SemAttNetConfig(branches=2, fusion="concat")),
    "table2_d": ("CG + SG + DG, concatenation", SemAttNetConfig(fusion="concat", refine=False)),
    "table2_e": ("CG + SG + DG, concatenation, CSPN++ refinement", SemAttNetConfig(fusion="concat")),
    "table2_f": ("CG + SG + DG, SAMMAFB (= semattnet_backbone)", SemAttNetConfig(refine=False)),
    "table2_g": ("CG + SG + DG, SAMMAFB, CSPN++ refinement (= semattnet)", SemAttNetConfig()),
}


def list_models() -> list[str]:
    """Names accepted by :func:`build_model`."""
    return list(MODELS)


def build_model(name: str = "semattnet", config: SemAttNetConfig | None = None, **overrides: Any) -> nn.Module:
    """Build a registered model, optionally changing config fields.

    Args:
        name: one of :func:`list_models`.
        config: a full config to use instead of the registered one (``name`` is then only
            checked).
        **overrides: config fields to replace, e.g. ``width=0.25`` or ``refinement_mode="clean"``.

    Returns:
        :class:`~semattnet.models.semattnet.SemAttNet` when ``refine`` is set, else
        :class:`~semattnet.models.backbone.SemAttNetBackbone`; freshly initialised (PyTorch defaults).

    Example:
        >>> import semattnet
        >>> net = semattnet.build_model("semattnet", width=0.25)
        >>> type(net).__name__
        'SemAttNet'
    """
    if name not in MODELS:
        raise ValueError(f"unknown model {name!r}; available: {', '.join(MODELS)}")
    cfg = config if config is not None else MODELS[name][1]
    if overrides:
        unknown = set(overrides) - set(cfg.to_dict())
        if unknown:
            raise ValueError(f"unknown config field(s) {sorted(unknown)}; fields: {sorted(cfg.to_dict())}")
        cfg = cfg.replace(**overrides)
    return SemAttNet(cfg) if cfg.refine else SemAttNetBackbone(cfg)


def describe_models(count_parameters: bool = False) -> str:
    """One line per registered model: name, (parameter count,) description."""
    lines = []
    for name, (description, _) in MODELS.items():
        count = f"{sum(p.numel() for p in build_model(name).parameters()):>13,d}  " if count_parameters else ""
        lines.append(f"{name:20s} {count}{description}")
    return "\n".join(lines)
