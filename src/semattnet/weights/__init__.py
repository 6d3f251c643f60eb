"""Weights: reading checkpoints without running their code, loading into models, conversion to
safetensors, ONNX / TorchScript export, the released-weights registry and fetching them through the
verified download cache (:mod:`semattnet.cache`, whose public names are also here).

Every weights spec (a registry name, a file, a ``save_pretrained`` folder, a URL) is read by one
function, :func:`resolve_weights`. Every model with weights is built by one function,
:func:`build_model_with_weights` (config from the weights, then overrides, then a strict load):
:func:`load_model`, :func:`from_pretrained`, :meth:`PretrainedWeights.build` and ``torch.hub``
(:func:`hub_model`) all call it.

Examples:
    >>> from semattnet import weights
    >>> weights.list_pretrained()[:3]
    ['semattnet-kitti', 'semattnet-demo-ref-seed0', 'semattnet-demo-ref-seed1']
    >>> [n for n in weights.list_pretrained() if n.startswith("semattnet-rt-md")]
    ['semattnet-rt-md-demo-seed0', 'semattnet-rt-md-demo-seed1']
    >>> weights.get_weights("semattnet-kitti").paper_metrics["kitti/test"]["rmse_mm"]
    709.41

Downloads need the ``hub`` extra (``pip install 'semattnet[hub]'``: pooch, huggingface_hub, gdown);
local files and folders need nothing more.
"""

from semattnet.cache import (
    ENV_CACHE,
    ENV_OFFLINE,
    ChecksumError,
    DownloadError,
    OfflineError,
    get_cache_dir,
    is_offline,
    read_pins,
    sha256_file,
)
from semattnet.weights.builder import WeightsMismatchError, build_model_with_weights
from semattnet.weights.checkpoint import (
    Checkpoint,
    CheckpointError,
    StateDictMismatchError,
    UnsafeCheckpointError,
    config_from_state_dict,
    filter_state_dict,
    load_checkpoint,
    load_weights,
    save_safetensors,
)
from semattnet.weights.hub import (
    CONFIG_NAME,
    WEIGHTS_NAME,
    from_pretrained,
    hub_model,
    load_model,
    push_to_hub,
    save_pretrained,
)
from semattnet.weights.packed import PACKED_FORMAT, read_packed, save_packed
from semattnet.weights.pretrained import (
    FORMATS,
    PretrainedWeights,
    UnknownWeightsError,
    default_weights,
    get_weights,
    list_pretrained,
    register_weights,
)
from semattnet.weights.resolve import (
    ResolvedWeights,
    ShadowedNameWarning,
    WeightsSpecError,
    fetch_weights,
    parse_weights_spec,
    resolve_weights,
)

__all__ = [
    "CONFIG_NAME",
    "ENV_CACHE",
    "ENV_OFFLINE",
    "FORMATS",
    "PACKED_FORMAT",
    "WEIGHTS_NAME",
    "Checkpoint",
    "CheckpointError",
    "ChecksumError",
    "DownloadError",
    "OfflineError",
    "PretrainedWeights",
    "ResolvedWeights",
    "ShadowedNameWarning",
    "StateDictMismatchError",
    "UnknownWeightsError",
    "UnsafeCheckpointError",
    "WeightsMismatchError",
    "WeightsSpecError",
    "build_model_with_weights",
    "config_from_state_dict",
    "default_weights",
    "fetch_weights",
    "filter_state_dict",
    "from_pretrained",
    "get_cache_dir",
    "get_weights",
    "hub_model",
    "is_offline",
    "list_pretrained",
    "load_checkpoint",
    "load_model",
    "load_weights",
    "parse_weights_spec",
    "push_to_hub",
    "read_packed",
    "read_pins",
    "register_weights",
    "resolve_weights",
    "save_packed",
    "save_pretrained",
    "save_safetensors",
    "sha256_file",
]
