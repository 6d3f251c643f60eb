"""Branch encoders behind one interface (:class:`Encoder`, :class:`FeatureInfo`) and their registry.

* :mod:`.base` the protocol, feature info and registry (:func:`create_encoder`, :func:`list_encoders`).
* :mod:`.resnet` the authors' ResNet-style encoder (``"resnet"``), the paper model's.
"""

from semattnet.models.encoders import resnet as _resnet  # noqa: F401  (registers "resnet")
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
from semattnet.models.encoders.resnet import ResNetEncoder

__all__ = [
    "Encoder",
    "EncoderSpec",
    "FeatureInfo",
    "ResNetEncoder",
    "StageHook",
    "UnknownEncoderError",
    "create_encoder",
    "encoder_spec",
    "list_encoders",
    "register_encoder",
]
