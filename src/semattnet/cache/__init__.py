"""A verified download cache: files fetched once, checked, moved into place atomically, offline-aware.

Split by concern:

* :mod:`.errors` ``DownloadError`` (an ``OSError`` and a ``SemAttNetError``), ``ChecksumError``, ``OfflineError``;
* :mod:`.store` the cache folder, the offline switch, sha256, locks and the pin file (trust on first use);
* :mod:`.transports` http(s) (huggingface_hub, resumable; pooch without it), Google Drive (gdown), file://;
* :mod:`.hf` ``hf://owner/repo[@revision][/file]`` through huggingface_hub;
* :mod:`.fetch` one file: cache hit verified, miss downloaded into a temporary file, checked, moved in.

``SEMATTNET_OFFLINE=1`` or ``HF_HUB_OFFLINE=1``: nothing touches the network; a cache hit works,
a miss raises :class:`OfflineError` naming the file and where to put it. (Both are read at each
call; huggingface_hub itself reads ``HF_HUB_OFFLINE`` once, when it is imported.)

Cache layout (``$SEMATTNET_CACHE``, default ``platformdirs.user_cache_dir("semattnet")``)::

    pins.json                              sha256, size, mtime and origin of every verified file
    <weights name>/<file name>             released weights (semattnet.weights registry records)
    urls/<sha256(url)[:16]>/<file name>    any other URL (e.g. the KITTI archives)
    converted/<source sha256>.safetensors  pickles converted once (semattnet.weights.hub)
    huggingface/                           hf:// downloads when the cache is set explicitly
    .locks/                                inter-process locks

The public face of the cache for every layer above it (weights, data, segmentation, the engines'
export cache, the demo); :func:`semattnet.weights.fetch_weights` adds registry names, ``semattnet data download``
the datasets' archives.
"""

from semattnet.cache.errors import ChecksumError, DownloadError, OfflineError
from semattnet.cache.fetch import Target, check_sha256, fetch, fetch_target, url_target
from semattnet.cache.hf import fetch_hf, parse_hf_url
from semattnet.cache.store import (
    ENV_CACHE,
    ENV_OFFLINE,
    PINS_FILE,
    cache_key,
    cache_lock,
    get_cache_dir,
    is_offline,
    pin_record,
    read_pins,
    remove_empty_dirs,
    sha256_file,
    sha256_tree,
    update_pins,
    verify_cached,
)
from semattnet.cache.transports import check_file_name, url_scheme

__all__ = [
    "ENV_CACHE",
    "ENV_OFFLINE",
    "PINS_FILE",
    "ChecksumError",
    "DownloadError",
    "OfflineError",
    "Target",
    "cache_key",
    "cache_lock",
    "check_file_name",
    "check_sha256",
    "fetch",
    "fetch_hf",
    "fetch_target",
    "get_cache_dir",
    "is_offline",
    "parse_hf_url",
    "pin_record",
    "read_pins",
    "remove_empty_dirs",
    "sha256_file",
    "sha256_tree",
    "update_pins",
    "url_scheme",
    "url_target",
    "verify_cached",
]
