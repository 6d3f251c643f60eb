"""The one reader of weights specs: ``NAME|PATH|URL`` -> local weights (:func:`resolve_weights`).

Every way to name weights goes through :func:`parse_weights_spec`, the only place that tells a
registry name, a local file or folder and a URL apart: :func:`~semattnet.weights.from_pretrained`,
:func:`~semattnet.weights.load_model`, ``DepthCompleter.from_pretrained`` / ``from_checkpoint``,
``torch.hub``, :func:`fetch_weights`, and every ``--weights`` of the command line (``semattnet info``,
``weights fetch``, ``train --init`` included).

A spec is one of

* a registry name (:func:`~semattnet.weights.list_pretrained`, e.g. ``semattnet-kitti`` or the shipped
  ``semattnet-demo-ref-seed0``) or a :class:`~semattnet.weights.PretrainedWeights` record;
* a local file (the authors' ``.pth.tar``, a torch checkpoint or state dict, ``.safetensors``, packed
  weights) or a folder written by :func:`~semattnet.weights.save_pretrained` (``config.json`` +
  ``model.safetensors``);
* a URL: ``http(s)://``, ``file://``, ``gdrive://<id>`` (a file) or ``hf://owner/repo[@revision][/file]``.

A registered name always means the registry's weights, even where a local file or folder of that name
exists (a :class:`ShadowedNameWarning` says so, once per call): the local one is ``./NAME`` (or a ``Path``).

A pickle that was downloaded is converted once to ``<cache>/converted/<sha256 of the pickle>.safetensors``
(:meth:`ResolvedWeights.load`); later loads read that file.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.bounds import regular_file
from semattnet._utils.documents import read_document
from semattnet.cache import (
    cache_key,
    cache_lock,
    check_sha256,
    fetch_hf,
    fetch_target,
    get_cache_dir,
    pin_record,
    remove_empty_dirs,
    sha256_file,
    update_pins,
    url_target,
    verify_cached,
)
from semattnet.cache import fetch as fetch_url
from semattnet.models.config import SemAttNetConfig
from semattnet.models.registry import MODELS
from semattnet.weights import builder
from semattnet.weights.checkpoint import (
    Checkpoint,
    CheckpointError,
    UnsafeCheckpointError,
    load_checkpoint,
    save_safetensors,
)
from semattnet.weights.download import weights_target
from semattnet.weights.packed import shipped_path
from semattnet.weights.pretrained import PretrainedWeights, UnknownWeightsError, get_weights, list_pretrained

__all__ = [
    "CONFIG_NAME",
    "URL_SCHEMES",
    "WEIGHTS_NAME",
    "ResolvedWeights",
    "ShadowedNameWarning",
    "WeightsSpec",
    "WeightsSpecError",
    "fetch_weights",
    "packed_file",
    "parse_weights_spec",
    "resolve_weights",
]

CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"
#: The URL schemes weights can come from.
URL_SCHEMES = ("http", "https", "file", "gdrive", "hf")
_META_KEYS = ("arch", "library_name", "library_version")

#: What a spec names: a registry record, a local file or folder, or a URL (kept as text).
WeightsSpec = PretrainedWeights | Path | str


class WeightsSpecError(UnknownWeightsError):
    """A weights spec that names no registered weights, existing file or folder, or URL."""


class ShadowedNameWarning(UserWarning):
    """A registered weights name was given while a local file or folder of that name exists: the registry's
    weights are used (``./NAME`` is the local one)."""


def parse_weights_spec(spec: str | os.PathLike[str] | PretrainedWeights) -> WeightsSpec:
    """The one parser of weights specs: a record (from a record or a registry name), a local ``Path``, or a URL.

    Nothing is read or fetched. A text with ``://`` is a URL (the cache names an unsupported scheme);
    else an existing file or folder; else a registry name.

    Raises:
        WeightsSpecError: none of these (the message lists the registered names).
    """
    if isinstance(spec, PretrainedWeights):
        return spec
    if isinstance(spec, os.PathLike):
        return Path(spec)
    if not isinstance(spec, str):
        raise WeightsSpecError(f"weights: expected a name, path or URL, got {type(spec).__name__}")
    if "://" in spec:
        return spec
    path = Path(spec).expanduser()
    if spec in list_pretrained():  # a name is the registry's: a local NAME is ./NAME (never a silent shadow)
        if path.exists():
            warnings.warn(
                f"weights {spec!r}: the registered weights are used, not the local {spec} here "
                f"(pass ./{spec} for that one)",
                ShadowedNameWarning,
                stacklevel=3,
            )
        return get_weights(spec)
    if path.exists():
        return path
    raise WeightsSpecError(
        f"{spec!r}: not an existing file or folder, a URL ({', '.join(s + '://' for s in URL_SCHEMES)}) or registered "
        f"weights; known: {', '.join(list_pretrained())}"
    )


@dataclass(frozen=True)
class ResolvedWeights:
    """Weights on this machine, and what is known about them.

    Attributes:
        path: a weights file, or a :func:`~semattnet.weights.save_pretrained` folder.
        label: how messages name the weights: ``weights 'NAME'``, the URL or the path.
        entry: the registry record, when the spec named one.
        config: the config recorded beside the weights (the record's, a folder's ``config.json``), else None.
        cache_root: the cache a downloaded file lies in (its pickle is converted there once), else None.
        digest: the sha256 of a downloaded file, else None.
    """

    path: Path
    label: str
    entry: PretrainedWeights | None = None
    config: SemAttNetConfig | None = None
    cache_root: Path | None = None
    digest: str | None = None

    @property
    def file(self) -> Path:
        """The weights file (a folder's ``model.safetensors``)."""
        return self.path / WEIGHTS_NAME if self.path.is_dir() else self.path

    @property
    def source(self) -> str | None:
        """The name of registry weights in messages (None: the file's path names them)."""
        return self.label if self.entry is not None else None

    def build(
        self,
        arch: str | None = None,
        overrides: Mapping[str, object] | None = None,
        device: str | torch.device = "cpu",
    ) -> nn.Module:
        """The model of these weights, in eval mode, through :func:`~semattnet.weights.build_model_with_weights`
        (``arch``: the model name they must be for; ``overrides``: config fields that keep the shapes)."""
        return builder.build_model_with_weights(
            self.load(), config=self.config, arch=arch, overrides=overrides, device=device, source=self.source
        )

    def load(self) -> Checkpoint:
        """The weights read without running code (:func:`~semattnet.weights.load_checkpoint`); a downloaded
        pickle is converted once to safetensors in the cache, and a downloaded file that is refused is removed."""
        if self.cache_root is None or self.digest is None:
            return load_checkpoint(self.file)
        return _load_download(self.cache_root, self.file, self.digest)


def resolve_weights(
    spec: str | os.PathLike[str] | PretrainedWeights,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    progress: bool = True,
) -> ResolvedWeights:
    """Local weights for ``spec`` (see the module docstring): a name or URL is fetched into the cache once.

    Args:
        spec: a registry name or record, a local file or folder, or a URL.
        sha256: expected sha256 of the downloaded (or shipped) file; for ``hf://owner/repo``: of its
            ``model.safetensors``.
        cache_dir: cache root (default ``$SEMATTNET_CACHE``, else the user cache folder).
        progress: show download progress.

    Raises:
        WeightsSpecError: ``spec`` names nothing.
        CheckpointError: a folder without ``model.safetensors`` or with a bad ``config.json``; a shipped file
            missing or changed.
        semattnet.cache.DownloadError: see :func:`semattnet.cache.fetch`.
    """
    source = parse_weights_spec(spec)
    sha256 = check_sha256(sha256)
    if isinstance(source, PretrainedWeights):
        return _from_entry(source, sha256, cache_dir, progress)
    if isinstance(source, Path):
        return _local(source, str(source))
    if source.startswith("hf://"):
        path = fetch_hf(source, sha256=sha256, cache_dir=cache_dir, allow_patterns=[CONFIG_NAME, WEIGHTS_NAME, "*.md"])
        return _local(path, source)
    root = get_cache_dir(cache_dir).resolve()
    path, digest = fetch_target(root, url_target(source, sha256, root), progress)
    return ResolvedWeights(path, source, cache_root=root, digest=digest)


def fetch_weights(
    url_or_entry: str | PretrainedWeights,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    file_name: str | None = None,
    progress: bool = True,
) -> Path:
    """Download a weights file into the cache (once) and return its local path.

    Args:
        url_or_entry: a :class:`PretrainedWeights` record, a registry name, or a URL:
            ``http(s)://``, ``file://``, ``gdrive://<id>`` or ``hf://owner/repo[@rev][/file]``
            (without a file, the repository folder is returned).
        sha256: expected hex digest (overrides the record's; None: the record's, else pinned on
            first download).
        cache_dir: cache root (default ``$SEMATTNET_CACHE`` or the platform's user cache folder).
        file_name: name of the cached file (default: the record's, or the URL's last path part).
        progress: show a progress bar.

    Raises:
        UnknownWeightsError: a name that is not in the registry.
        ChecksumError: the file does not match its checksum or size; nothing is left in the cache.
        OfflineError: offline mode and the file is not cached.
        DownloadError: every URL failed (the message lists each failure).
    """
    sha256 = check_sha256(sha256)
    source = parse_weights_spec(url_or_entry)
    if isinstance(source, str):
        return fetch_url(source, sha256=sha256, cache_dir=cache_dir, file_name=file_name, progress=progress)
    if not isinstance(source, PretrainedWeights):
        raise WeightsSpecError(f"fetch: {url_or_entry!r} is a local path, not a name or URL")
    root = get_cache_dir(cache_dir).resolve()
    return fetch_target(root, weights_target(source, sha256, root, file_name), progress)[0]


def packed_file(entry: PretrainedWeights, sha256: str | None = None) -> Path:
    """The shipped file of a ``packed`` record, its sha256 checked (``sha256`` else the record's)."""
    path = shipped_path(entry.file_name)
    expected = sha256 or entry.sha256
    if not path.is_file():
        raise CheckpointError(f"weights {entry.name!r}: {path} is missing from the installed package; reinstall it")
    if expected is not None and sha256_file(path) != expected:
        raise CheckpointError(f"weights {entry.name!r}: {path} does not match its sha256 {expected}; reinstall")
    return path


def _from_entry(
    entry: PretrainedWeights, sha256: str | None, cache_dir: str | os.PathLike[str] | None, progress: bool
) -> ResolvedWeights:
    """A registry record: its shipped file, its ``hf://`` folder or its downloaded file; the record's config."""
    label, config = f"weights {entry.name!r}", entry.model_config()
    if entry.format == "packed":
        return ResolvedWeights(packed_file(entry, sha256), label, entry, config)
    if entry.format == "hf-folder":
        url = next((u for u in entry.urls if u.startswith("hf://")), None)
        if url is None:
            raise InputError(f"weights {entry.name!r}: format 'hf-folder' needs an hf:// URL")
        folder = fetch_hf(url, sha256=sha256 or entry.sha256, cache_dir=cache_dir)
        return ResolvedWeights(_folder_weights(folder).parent, label, entry, config)
    root = get_cache_dir(cache_dir).resolve()
    path, digest = fetch_target(root, weights_target(entry, sha256, root), progress)
    return ResolvedWeights(path, label, entry, config, root, digest)


def _local(path: Path, label: str) -> ResolvedWeights:
    """A file as it is; a folder's ``model.safetensors`` (checked) and its ``config.json`` when it has one."""
    if not path.is_dir():
        return ResolvedWeights(path, label)
    _folder_weights(path)
    config = read_folder_config(path)[1] if (path / CONFIG_NAME).is_file() else None
    return ResolvedWeights(path, label, config=config)


def _folder_weights(folder: Path) -> Path:
    """``folder/model.safetensors``; present names that are not regular files are refused, never skipped."""
    for name in (WEIGHTS_NAME, CONFIG_NAME):  # present but a FIFO / device / folder: never skipped silently
        if (folder / name).exists() and not (folder / name).is_file():
            regular_file(folder / name, name, CheckpointError)
    weights = folder / WEIGHTS_NAME
    if not weights.is_file():
        present = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
        raise CheckpointError(f"{folder}: no {WEIGHTS_NAME} (found: {', '.join(present) or 'nothing'})")
    return weights


def read_folder_config(folder: Path) -> tuple[str, SemAttNetConfig]:
    """The registry model name and config of a saved folder's ``config.json``."""
    path = folder / CONFIG_NAME
    data = read_document(path, error=CheckpointError)  # bounded size and nesting
    if not isinstance(data, dict):
        raise CheckpointError(f"{path}: expected a JSON object")
    arch = data.get("arch", "semattnet")
    if not isinstance(arch, str) or arch not in MODELS:  # a list would fail as unhashable
        raise CheckpointError(f"{path}: unknown arch {arch!r}; available: {', '.join(MODELS)}")
    fields = {k: v for k, v in data.items() if k not in _META_KEYS}
    known = set(SemAttNetConfig().to_dict())
    unknown = sorted(set(fields) - known)
    if unknown:
        raise CheckpointError(f"{path}: unknown config field(s) {unknown}; fields: {sorted(known)}")
    try:
        cfg = MODELS[arch].config.replace(**fields)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: invalid config: {exc}") from exc
    return arch, cfg


def _is_safetensors(path: Path) -> bool:
    """An 8-byte little-endian header length, then the JSON header (a torch zip starts with PK)."""
    with open(path, "rb") as f:
        head = f.read(9)
    return len(head) == 9 and head[8:9] == b"{" and not head.startswith(b"PK")


def _load_download(root: Path, path: Path, digest: str) -> Checkpoint:
    """A downloaded file: safetensors as is; a pickle through its converted copy (made once)."""
    if _is_safetensors(path):
        return _read(root, path)
    converted = root / "converted" / f"{digest}.safetensors"
    if converted.is_file():
        try:
            verify_cached(root, converted, None, announce=False)
            return load_checkpoint(converted)
        except (OSError, CheckpointError):
            converted.unlink(missing_ok=True)  # damaged: convert again
    with cache_lock(root, cache_key(root, converted)):
        ckpt = _read(root, path)  # the safe unpickler; refuses code, removes the file if refused
        save_safetensors(ckpt, converted)
        origin = f"converted from {cache_key(root, path)}"
        record = pin_record(converted, sha256_file(converted), origin, "converted")
        update_pins(root, cache_key(root, converted), record)
    return ckpt


def _read(root: Path, path: Path) -> Checkpoint:
    """``load_checkpoint`` for a cached download; a file it refuses is removed from the cache."""
    try:
        return load_checkpoint(path)
    except (UnsafeCheckpointError, CheckpointError):
        path.unlink(missing_ok=True)
        update_pins(root, cache_key(root, path), None)
        remove_empty_dirs(path.parent, root)
        raise
