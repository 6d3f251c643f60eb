"""The encoder interface: what a branch needs from its encoder, and the registry of encoders.

An encoder maps a branch's input to features at a few strides. Its :class:`FeatureInfo` says which
(channels per stride, as timm's ``feature_info``), so the branch sizes its decoder, fusion blocks
and heads from it instead of assuming the ResNet doubling. Between stages a branch may fuse
guidance into the features (SAMMAFB, paper Sec. III-A): the encoder calls a :data:`StageHook`
after every stage and feeds its result to the next stage, whose input then has the stage's width
plus ``extra[i]`` channels (what the fusion concatenated).

A new encoder is one module implementing :class:`Encoder` plus one :func:`register_encoder` row.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch

from semattnet._errors import InputError
from semattnet._utils.registry import Registry, UnknownEntryError

__all__ = [
    "ENCODERS",
    "Encoder",
    "EncoderFactory",
    "EncoderSpec",
    "FeatureInfo",
    "StageHook",
    "UnknownEncoderError",
    "create_encoder",
    "encoder_spec",
    "list_encoders",
    "register_encoder",
]

#: ``hook(stage_index, features) -> next stage's input``; the identity when a branch fuses nothing.
StageHook = Callable[[int, torch.Tensor], torch.Tensor]


@dataclass(frozen=True)
class FeatureInfo:
    """Channels of an encoder's features per stride (relative to the encoder's input), shallow to deep.

    ``stem`` is the stem's output (stride ``strides[0] // 2`` or 1), the first skip of a decoder.
    """

    stem_channels: int
    stem_stride: int
    strides: tuple[int, ...]
    channels: tuple[int, ...]

    def __post_init__(self) -> None:
        if len(self.strides) != len(self.channels) or not self.strides:
            raise InputError(f"feature info: {len(self.strides)} strides for {len(self.channels)} channel counts")
        if any(c < 1 for c in (self.stem_channels, *self.channels)):
            raise InputError(f"feature info: channels must be positive, got {(self.stem_channels, *self.channels)}")

    def channels_at(self, stride: int) -> int:
        """Channels of the features at ``stride`` (the stem's at :attr:`stem_stride`)."""
        if stride == self.stem_stride:
            return self.stem_channels
        if stride not in self.strides:
            raise InputError(f"no features at stride {stride}; strides: {(self.stem_stride, *self.strides)}")
        return self.channels[self.strides.index(stride)]


@runtime_checkable
class Encoder(Protocol):
    """A branch encoder: ``encoder(x, hook)`` -> ``(stem, [features per stage])``.

    The returned stage features are the stages' own outputs (before ``hook``), shaped
    ``(B, feature_info.channels[i], H / strides[i], W / strides[i])``.
    """

    feature_info: FeatureInfo

    def __call__(self, x: torch.Tensor, hook: StageHook | None = None) -> tuple[torch.Tensor, list[torch.Tensor]]: ...


class EncoderFactory(Protocol):
    """Builds an encoder: ``in_chans`` input channels, ``channels`` per stage (stem first), ``extra`` channels
    a :data:`StageHook` adds to each stage's output before the next stage (default none)."""

    def __call__(self, in_chans: int, channels: Sequence[int], extra: Sequence[int] | None = None) -> Encoder: ...


@dataclass(frozen=True)
class EncoderSpec:
    """One registered encoder: its factory, a one-line description, its stem stride and default widths."""

    name: str
    factory: EncoderFactory
    description: str
    stem_stride: int
    channels: tuple[int, ...]  # stem, then one per stage (stride 2x the previous)


#: The registry's one unknown-name error (the old name kept).
UnknownEncoderError = UnknownEntryError

#: Encoder name -> :class:`EncoderSpec`, in registration order (the authors' ResNet first).
ENCODERS: Registry[EncoderSpec] = Registry("encoder")


def register_encoder(spec: EncoderSpec) -> EncoderSpec:
    """Add ``spec`` to :data:`ENCODERS` (a name is registered once)."""
    return ENCODERS.add(spec.name, spec)


def list_encoders() -> list[str]:
    """The registered encoder names, in registration order (the authors' ResNet first)."""
    return ENCODERS.names()


def encoder_spec(name: str) -> EncoderSpec:
    """The registry row of ``name``.

    Raises:
        UnknownEntryError: one line listing the registered names.
    """
    return ENCODERS[name]


def create_encoder(
    name: str, in_chans: int, channels: Sequence[int] | None = None, extra: Sequence[int] | None = None
) -> Encoder:
    """Build the registered encoder ``name`` (its default ``channels`` unless given)."""
    spec = encoder_spec(name)
    chans = tuple(spec.channels if channels is None else channels)
    if len(chans) < 2 or any(not isinstance(c, int) or c < 1 for c in chans):
        raise InputError(f"encoder {name!r}: channels must be 2+ positive integers (stem first), got {chans!r}")
    if extra is not None and len(extra) != len(chans) - 1:
        raise InputError(f"encoder {name!r}: {len(extra)} extra widths for {len(chans) - 1} stages")
    return spec.factory(in_chans, chans, extra)
