"""Branch encoders behind one interface (:class:`Encoder`, :class:`FeatureInfo`) and their registry.

* :mod:`.base` the protocol, feature info and registry (:func:`create_encoder`, :func:`list_encoders`).
* :mod:`.resnet` the authors' ResNet-style encoder (``"resnet"``), the paper model's.
* :mod:`.lite` depthwise-separable encoders with a stride-2 or stride-4 stem (``"lite_s2"``, ``"lite_s4"``),
  the real-time variants' (:mod:`semattnet.models.rt`).
"""

from functools import partial

from semattnet.models.encoders.base import (
    Encoder,
    EncoderSpec,
    FeatureInfo,
    StageHook,
    UnknownEncoderError,
    create_encoder,
    encoder_spec,
    list_encoders,
    register_encoder,
)
from semattnet.models.encoders.lite import LiteEncoder
from semattnet.models.encoders.resnet import ResNetEncoder

# The registry: one row per encoder (the authors' first). Widths: the stem's, then one per stage.
register_encoder(
    EncoderSpec(
        "resnet",
        ResNetEncoder,
        "the authors' ResNet-style encoder (2 basic blocks a stage)",
        stem_stride=1,
        channels=(32, 64, 128, 256, 512, 1024),
    )
)
register_encoder(
    EncoderSpec(
        "lite_s4",
        partial(LiteEncoder, stem_stride=4),
        "depthwise-separable, stem to 1/4",
        stem_stride=4,
        channels=(16, 24, 32, 48),
    )
)
register_encoder(
    EncoderSpec(
        "lite_s2",
        partial(LiteEncoder, stem_stride=2),
        "depthwise-separable, stem to 1/2",
        stem_stride=2,
        channels=(12, 16, 24, 32, 48),
    )
)
register_encoder(
    EncoderSpec(
        "lite_s2_deep",
        partial(LiteEncoder, stem_stride=2),
        "depthwise-separable, stem to 1/2, channels doubling with each stage",
        stem_stride=2,
        channels=(12, 24, 48, 96, 192),
    )
)
register_encoder(
    EncoderSpec(
        "lite_s4_wide",
        partial(LiteEncoder, stem_stride=4),
        "depthwise-separable, stem to 1/4, twice lite_s4's channels",
        stem_stride=4,
        channels=(32, 48, 64, 96),
    )
)

__all__ = [
    "Encoder",
    "EncoderSpec",
    "FeatureInfo",
    "LiteEncoder",
    "ResNetEncoder",
    "StageHook",
    "UnknownEncoderError",
    "create_encoder",
    "encoder_spec",
    "list_encoders",
    "register_encoder",
]
