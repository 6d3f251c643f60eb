"""SemAttNet: attention-based semantic-aware guided depth completion (Nazir et al., IEEE Access 2022).

The package is laid out as the system is (see the README's "Architecture" section):
:mod:`semattnet.models` (the network), :mod:`semattnet.weights` (checkpoints), :mod:`semattnet.palette`
(class colours), :mod:`semattnet.data` (KITTI, synthetic scenes, PNG I/O), :mod:`semattnet.segmentation`,
:mod:`semattnet.training`, :mod:`semattnet.evaluation`, :mod:`semattnet.inference`,
:mod:`semattnet.baselines`, :mod:`semattnet.viz`, :mod:`semattnet.apps` and :mod:`semattnet.cli`.
The names below are the stable public API.
"""

from semattnet import palette, robotics  # robotics: enrols the bag source and the robot sinks
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
from semattnet.weights import (
    from_pretrained,
    get_weights,
    list_pretrained,
    load_checkpoint,
    load_model,
    load_weights,
    push_to_hub,
    save_pretrained,
)

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
    "get_weights",
    "list_models",
    "list_pretrained",
    "load_checkpoint",
    "load_model",
    "load_weights",
    "pad_to_multiple",
    "palette",
    "push_to_hub",
    "robotics",
    "save_pretrained",
]
