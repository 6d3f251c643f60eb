"""Released weights: a registry, a verified download cache and ``from_pretrained``.

>>> import semattnet.hub as hub
>>> hub.list_pretrained()
['semattnet-kitti']
>>> hub.get_weights("semattnet-kitti").paper_metrics["kitti/test"]["rmse_mm"]
709.41

Downloads need the ``hub`` extra (``pip install 'semattnet[hub]'``: pooch, huggingface_hub, gdown);
local files and folders need nothing more.
"""

from __future__ import annotations

from .api import CONFIG_NAME, WEIGHTS_NAME, from_pretrained, hub_model, push_to_hub, save_pretrained
from .download import (
    ENV_CACHE,
    ENV_OFFLINE,
    ChecksumError,
    DownloadError,
    OfflineError,
    fetch,
    get_cache_dir,
    is_offline,
    read_pins,
    sha256_file,
)
from .pretrained import (
    FORMATS,
    PretrainedWeights,
    UnknownWeightsError,
    default_weights,
    get_weights,
    list_pretrained,
    register_weights,
)

__all__ = [
    "CONFIG_NAME",
    "ENV_CACHE",
    "ENV_OFFLINE",
    "FORMATS",
    "WEIGHTS_NAME",
    "ChecksumError",
    "DownloadError",
    "OfflineError",
    "PretrainedWeights",
    "UnknownWeightsError",
    "default_weights",
    "fetch",
    "from_pretrained",
    "get_cache_dir",
    "get_weights",
    "hub_model",
    "is_offline",
    "list_pretrained",
    "push_to_hub",
    "read_pins",
    "register_weights",
    "save_pretrained",
    "sha256_file",
]
