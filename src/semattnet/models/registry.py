"""Model registry: ``build_model(name, **overrides)``, the variants of the paper and their aliases.

``semattnet`` and ``semattnet_backbone`` are the released models (authors' parameter names);
``table2_a`` ... ``table2_e`` are the ablations of the paper's Table 2. Rows (f) and (g) of
Table 2 *are* the backbone and the full model, so ``table2_f`` and ``table2_g`` are aliases of
them rather than rows of their own: :func:`list_models` names each architecture once, every alias
resolves (:func:`resolve_model_name`), and :func:`describe_models` lists the aliases.

``semattnet_rt_s`` and ``semattnet_rt_m`` are real-time variants (:mod:`semattnet.models.rt`): the paper's
structure on a light encoder (:mod:`semattnet.models.encoders`) at 1/4 and 1/2 resolution.

The model class (full model with refinement vs backbone alone, paper vs real-time) is chosen in one
place, :func:`model_class`, from the config's ``refine`` and ``encoder`` fields.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.registry import Registry, UnknownEntryError
from semattnet.models.backbone import SemAttNetBackbone
from semattnet.models.config import SemAttNetConfig
from semattnet.models.generalist import Generalist
from semattnet.models.macs import count_macs
from semattnet.models.rt import SemAttNetRT, SemAttNetRTBackbone
from semattnet.models.semattnet import SemAttNet

__all__ = [
    "ALIASES",
    "ARCH_FIELDS",
    "MODELS",
    "TABLE2",
    "ModelSpec",
    "UnknownModelError",
    "arch_for",
    "build_model",
    "describe_models",
    "list_models",
    "model_class",
    "model_config",
    "resolve_model_name",
]

#: The config fields a registered name fixes (the rest, e.g. ``width``, are free).
ARCH_FIELDS = ("branches", "fusion", "refine", "encoder", "anchor", "work_scale")


#: The registry's one unknown-name error (the old name kept).
UnknownModelError = UnknownEntryError


@dataclass(frozen=True)
class ModelSpec:
    """One registered architecture: its name, a one-line description, its config and its aliases."""

    name: str
    description: str
    config: SemAttNetConfig
    aliases: tuple[str, ...] = ()


_SPECS = (
    ModelSpec(
        "semattnet",
        "Full SemAttNet: three branches, SAMMAFB, CSPN++ refinement (Table 2 g)",
        SemAttNetConfig(),
        ("table2_g",),
    ),
    ModelSpec(
        "semattnet_backbone",
        "Three-branch backbone with SAMMAFB, no refinement (Table 2 f)",
        SemAttNetConfig(refine=False),
        ("table2_f",),
    ),
    ModelSpec("table2_a", "CG + DG, fusion by addition", SemAttNetConfig(branches=2, fusion="add", refine=False)),
    ModelSpec(
        "table2_b", "CG + DG, fusion by concatenation", SemAttNetConfig(branches=2, fusion="concat", refine=False)
    ),
    ModelSpec("table2_c", "CG + DG, concatenation, CSPN++ refinement", SemAttNetConfig(branches=2, fusion="concat")),
    ModelSpec("table2_d", "CG + SG + DG, concatenation", SemAttNetConfig(fusion="concat", refine=False)),
    ModelSpec("table2_e", "CG + SG + DG, concatenation, CSPN++ refinement", SemAttNetConfig(fusion="concat")),
    ModelSpec(
        "semattnet_rt_s",
        "Real-time: the paper's structure at 1/4 resolution, separable blocks, CSPN++ at 1/4",
        SemAttNetConfig(encoder="lite_s4", reduction=4, kernel_sizes=(3,), iterations=4),
    ),
    ModelSpec(
        "semattnet_rt_m",
        "Real-time: the paper's structure at 1/2 resolution, separable blocks, CSPN++ at 1/2",
        SemAttNetConfig(encoder="lite_s2", reduction=4, kernel_sizes=(3,), iterations=4),
    ),
    ModelSpec(
        "semattnet_rt_md",
        "Real-time: rt_m with channels doubling at every stage (1/2 resolution), convex propagation kernels",
        SemAttNetConfig(encoder="lite_s2_deep", reduction=4, kernel_sizes=(3,), iterations=4, affinity="convex"),
    ),
    ModelSpec(
        "semattnet_rt_l",
        "Real-time: semattnet_rt_s with twice its channels (1/4 resolution, CSPN++ at 1/4)",
        SemAttNetConfig(encoder="lite_s4_wide", reduction=4, kernel_sizes=(3,), iterations=4),
    ),
    ModelSpec(
        "semattnet_generalist",
        "Generalist: the full model, scale-free, correcting the classical completion (models.generalist)",
        SemAttNetConfig(width=0.125, anchor="classical"),
    ),
    ModelSpec(
        "semattnet_half_generalist",
        "Generalist: semattnet_generalist whose network works at half resolution (its anchor at full)",
        SemAttNetConfig(width=0.125, anchor="classical", work_scale=2),
    ),
    ModelSpec(
        "semattnet_rt_generalist",
        "Generalist: semattnet_rt_md, scale-free, correcting the classical completion (models.generalist)",
        SemAttNetConfig(
            encoder="lite_s2_deep", reduction=4, kernel_sizes=(3,), iterations=4, affinity="convex", anchor="classical"
        ),
    ),
    ModelSpec(
        "semattnet_rt_half_generalist",
        "Generalist: semattnet_rt_generalist whose network works at half resolution (its anchor at full)",
        SemAttNetConfig(
            encoder="lite_s2_deep",
            reduction=4,
            kernel_sizes=(3,),
            iterations=4,
            affinity="convex",
            anchor="classical",
            work_scale=2,
        ),
    ),
    ModelSpec(
        "semattnet_rt_l_generalist",
        "Generalist: semattnet_rt_l, scale-free, correcting the classical completion (models.generalist)",
        SemAttNetConfig(encoder="lite_s4_wide", reduction=4, kernel_sizes=(3,), iterations=4, anchor="classical"),
    ),
)
#: Name -> :class:`ModelSpec`, each architecture once; its aliases (``table2_f``, ``table2_g``) are accepted as keys
#: (``MODELS["table2_g"]``) but iteration, ``len`` and ``names()`` give each architecture once.
MODELS: Registry[ModelSpec] = Registry("model")
for _spec in _SPECS:
    MODELS.add(_spec.name, _spec)
    for _alias in _spec.aliases:
        MODELS.alias(_alias, _spec.name)

#: alias -> registered name.
ALIASES: Mapping[str, str] = MODELS.aliases
#: The rows (a) ... (g) of the paper's Table 2, in order (``table2_f``/``table2_g`` are aliases).
TABLE2: tuple[str, ...] = tuple(f"table2_{row}" for row in "abcdefg")


def resolve_model_name(name: str) -> str:
    """The registered name for ``name`` (itself, or what the alias stands for).

    Raises:
        UnknownEntryError: one line listing the names and aliases.
    """
    return MODELS.resolve(name)


def list_models() -> list[str]:
    """The registered names, each architecture once (aliases: :data:`ALIASES`)."""
    return MODELS.names()


def model_config(name: str) -> SemAttNetConfig:
    """The registered config of ``name`` (or an alias)."""
    return MODELS[name].config


def model_class(cfg: SemAttNetConfig) -> type[nn.Module]:
    """The class a config builds: :class:`SemAttNet` with ``refine``, else :class:`SemAttNetBackbone`;
    their real-time twins (:mod:`semattnet.models.rt`) for a light ``encoder``; :class:`Generalist` (around
    either) for a config with an ``anchor``."""
    if cfg.anchor != "none":
        return Generalist
    if cfg.realtime:
        return SemAttNetRT if cfg.refine else SemAttNetRTBackbone
    return SemAttNet if cfg.refine else SemAttNetBackbone


def arch_for(cfg: SemAttNetConfig) -> str:
    """The registered name whose :data:`ARCH_FIELDS` equal ``cfg``'s (the paper's models first)."""
    key = tuple(getattr(cfg, f) for f in ARCH_FIELDS)
    for spec in _SPECS:
        if tuple(getattr(spec.config, f) for f in ARCH_FIELDS) == key:
            return spec.name
    if cfg.anchor != "none":  # a generalist of another width or kernel
        return "semattnet_rt_generalist" if cfg.realtime else "semattnet_generalist"
    if cfg.realtime:  # the first real-time row on the same encoder (any real-time row for a new encoder)
        rows = [s.name for s in _SPECS if s.config.realtime]
        return next((s.name for s in _SPECS if s.config.encoder == cfg.encoder), rows[0])
    return "semattnet" if cfg.refine else "semattnet_backbone"  # a combination the paper did not name


def _check_overrides(cfg: SemAttNetConfig, overrides: Mapping[str, object]) -> None:
    unknown = set(overrides) - set(cfg.to_dict())
    if unknown:
        raise InputError(f"unknown config field(s) {sorted(unknown)}; fields: {sorted(cfg.to_dict())}")


def build_model(name: str | None = None, config: SemAttNetConfig | None = None, **overrides: object) -> nn.Module:
    """Build a registered model, optionally changing config fields.

    ``name`` selects the architecture and its base config; ``config`` replaces the base config and
    must be of the same architecture (equal :data:`ARCH_FIELDS`: ``branches``, ``fusion``,
    ``refine``), else :class:`~semattnet.InputError`; ``overrides`` then change any field. With
    ``config`` and no ``name``, the architecture is the config's own.

    Args:
        name: one of :func:`list_models` or an alias (:data:`ALIASES`); default ``"semattnet"``
            (or, with ``config``, the config's architecture).
        config: a full config to build instead of the registered one.
        **overrides: config fields to replace, e.g. ``width=0.25`` or ``refinement_mode="clean"``.

    Returns:
        :class:`~semattnet.models.semattnet.SemAttNet` when ``refine`` is set, else
        :class:`~semattnet.models.backbone.SemAttNetBackbone` (:func:`model_class`); freshly
        initialised (PyTorch defaults).

    Example:
        >>> import semattnet
        >>> net = semattnet.build_model("semattnet", width=0.25)
        >>> type(net).__name__
        'SemAttNet'
    """
    if name is None:
        cfg = config if config is not None else model_config("semattnet")
    else:
        base = model_config(name)
        cfg = base if config is None else config
        wrong = [
            f"{f}={getattr(cfg, f)!r} (the model has {getattr(base, f)!r})"
            for f in ARCH_FIELDS
            if getattr(cfg, f) != getattr(base, f)
        ]
        if wrong:
            raise InputError(
                f"build_model({name!r}, config=...): the config is not of that architecture: "
                f"{', '.join(wrong)}; pass config alone, or name {arch_for(cfg)!r}"
            )
    if overrides:
        _check_overrides(cfg, overrides)
        cfg = cfg.replace(**overrides)
    return model_class(cfg)(cfg)


def describe_models(count_parameters: bool = False) -> str:
    """One line per registered architecture: name, (parameter count, GMAC,) description, aliases.

    GMAC: multiply-accumulates of one 352x1216 frame (the paper's model at width 1 has about 530, at width 1/8
    about 8), counted on a 352x64 strip and scaled by the area.
    """
    lines = []
    for spec in _SPECS:
        count = f"{_params_and_macs(spec):>27s}  " if count_parameters else ""
        also = f" [alias: {', '.join(spec.aliases)}]" if spec.aliases else ""
        lines.append(f"{spec.name:20s} {count}{spec.description}{also}")
    return "\n".join(lines)


def _params_and_macs(spec: ModelSpec) -> str:
    """Parameters and the GMAC of one 352x1216 frame. The models are fully convolutional, so their convolutions'
    MACs scale with the image's area: counted on a 352x64 strip (every stride's maps a whole number of pixels
    wide) and multiplied by 19 (= 1216 / 64), a width-1 forward of a few seconds instead of a minute. Only the
    channel attention's linear layers, a few thousand MACs a frame, do not scale."""
    model = build_model(spec.name)
    text = f"{sum(p.numel() for p in model.parameters()):,d}"
    h, w = 352, 64
    strip = {"rgb": torch.zeros(1, 3, h, w), "semantic": torch.zeros(1, 3, h, w), "sparse": torch.zeros(1, 1, h, w)}
    return f"{text} {1216 // w * count_macs(model.eval(), strip):7.2f} GMAC"
