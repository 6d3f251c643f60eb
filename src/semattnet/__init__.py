"""SemAttNet: attention-based semantic-aware guided depth completion (Nazir et al., IEEE Access 2022)."""

from .backbone import SemAttNetBackbone
from .checkpoint import load_checkpoint, load_model, load_weights
from .config import SemAttNetConfig
from .model import SemAttNet
from .outputs import DepthCompletionOutput
from .registry import build_model, list_models
from .validation import crop_padding, pad_to_multiple

__version__ = "0.1.0"

__all__ = [
    "DepthCompletionOutput",
    "SemAttNet",
    "SemAttNetBackbone",
    "SemAttNetConfig",
    "__version__",
    "build_model",
    "crop_padding",
    "list_models",
    "load_checkpoint",
    "load_model",
    "load_weights",
    "pad_to_multiple",
]
