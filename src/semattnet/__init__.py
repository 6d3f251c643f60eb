"""SemAttNet: attention-based semantic-aware guided depth completion (Nazir et al., IEEE Access 2022).

The package is laid out as the system is (see the README's "Architecture" section):
:mod:`semattnet.models` (the network), :mod:`semattnet.weights` (checkpoints), :mod:`semattnet.palette`
(class colours), :mod:`semattnet.data` (KITTI, PNG I/O), :mod:`semattnet.synthetic` (synthetic scenes),
:mod:`semattnet.segmentation`, :mod:`semattnet.training`, :mod:`semattnet.evaluation`, :mod:`semattnet.inference`,
:mod:`semattnet.baselines`, :mod:`semattnet.viz`, :mod:`semattnet.apps` and :mod:`semattnet.cli`.
The names below are the stable public API; :func:`from_pretrained` is the one loader (the lower-level ones live in
:mod:`semattnet.weights`).
"""

# first, before anything imports torch: a Ctrl-C while the command line starts is one line, not a traceback
from semattnet import _startup  # noqa: F401

# isort: split
# robotics: enrols the bag source and the robot sinks; _moved: the synthetic scenes' old paths (deprecated until 0.3)
from semattnet import _moved, palette, robotics  # noqa: F401
from semattnet._errors import DataError, InputError, MissingDependencyError, SemAttNetError
from semattnet._utils.version import __version__
from semattnet.inference import DepthCompleter, crop_padding, pad_to_multiple
from semattnet.models import (
    DepthCompletionOutput,
    SemAttNet,
    SemAttNetBackbone,
    SemAttNetConfig,
    build_model,
    list_models,
)
from semattnet.weights import from_pretrained, list_pretrained, push_to_hub, save_pretrained

__all__ = [
    "DataError",
    "DepthCompleter",
    "DepthCompletionOutput",
    "InputError",
    "MissingDependencyError",
    "SemAttNet",
    "SemAttNetBackbone",
    "SemAttNetConfig",
    "SemAttNetError",
    "__version__",
    "build_model",
    "crop_padding",
    "from_pretrained",
    "list_models",
    "list_pretrained",
    "pad_to_multiple",
    "palette",
    "push_to_hub",
    "robotics",
    "save_pretrained",
]

#: The loaders that were at the root before 0.2 -> where they live now (deprecated here, gone in 0.3).
_MOVED = {
    "get_weights": "semattnet.weights.get_weights",
    "load_checkpoint": "semattnet.weights.load_checkpoint",
    "load_weights": "semattnet.weights.load_weights",
    "load_model": "semattnet.from_pretrained",
}


def __getattr__(name: str) -> object:
    """The loaders moved off the root, with a ``DeprecationWarning`` naming their home."""
    if name in _MOVED:
        import warnings

        from semattnet import weights

        warnings.warn(
            f"semattnet.{name} is deprecated since 0.2 and goes in 0.3: use {_MOVED[name]}",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(weights, name)
    raise AttributeError(f"module 'semattnet' has no attribute {name!r}")
