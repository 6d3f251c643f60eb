"""SemAttNet: attention-based semantic-aware guided depth completion (Nazir et al., IEEE Access 2022)."""

from .backbone import SemAttNetBackbone
from .config import SemAttNetConfig
from .model import SemAttNet
from .outputs import DepthCompletionOutput
from .registry import build_model, list_models

__version__ = "0.1.0"

__all__ = [
    "DepthCompletionOutput",
    "SemAttNet",
    "SemAttNetBackbone",
    "SemAttNetConfig",
    "__version__",
    "build_model",
    "list_models",
]
