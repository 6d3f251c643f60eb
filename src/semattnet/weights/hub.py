"""``from_pretrained`` / ``save_pretrained`` / ``push_to_hub``: a model from a name, file, folder or URL.

Every file is read through :func:`semattnet.checkpoint.load_checkpoint`, which never runs pickled
code. A pickle that was downloaded (the authors' ``.pth.tar`` or a torch checkpoint) is converted
once to ``<cache>/converted/<sha256 of the pickle>.safetensors``; later loads read that file.

A saved folder (``save_pretrained``, and what ``push_to_hub`` uploads) holds:

* ``config.json``: the :class:`~semattnet.SemAttNetConfig` fields plus ``arch`` (the registry
  model name), ``library_name`` and ``library_version``;
* ``model.safetensors``: the state dict (the config is also in its metadata);
* ``README.md``: a short model card.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.bounds import regular_file
from semattnet._utils.documents import read_document
from semattnet._utils.download import (
    OfflineError,
    cache_key,
    cache_lock,
    fetch_hf,
    fetch_target,
    get_cache_dir,
    is_offline,
    pin_record,
    remove_empty_dirs,
    sha256_file,
    update_pins,
    url_scheme,
    verify_cached,
)
from semattnet._utils.extras import require
from semattnet._utils.version import library_version
from semattnet.models.config import SemAttNetConfig
from semattnet.models.registry import MODELS, arch_for
from semattnet.weights import builder
from semattnet.weights.checkpoint import (
    Checkpoint,
    CheckpointError,
    UnsafeCheckpointError,
    config_from_state_dict,
    load_checkpoint,
    save_safetensors,
)
from semattnet.weights.download import is_url, weights_target
from semattnet.weights.packed import shipped_path
from semattnet.weights.pretrained import PretrainedWeights, default_weights, get_weights, list_pretrained

__all__ = [
    "CONFIG_NAME",
    "WEIGHTS_NAME",
    "from_pretrained",
    "hub_model",
    "load_model",
    "packed_file",
    "push_to_hub",
    "save_pretrained",
]

CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"
_META_KEYS = ("arch", "library_name", "library_version")


def _is_safetensors(path: Path) -> bool:
    """An 8-byte little-endian header length, then the JSON header (a torch zip starts with PK)."""
    with open(path, "rb") as f:
        head = f.read(9)
    return len(head) == 9 and head[8:9] == b"{" and not head.startswith(b"PK")


@dataclass(frozen=True)
class _Load:
    """What one ``from_pretrained`` call asks for, passed down to the builder."""

    sha256: str | None
    cache_dir: str | os.PathLike[str] | None
    device: str | torch.device
    progress: bool
    overrides: dict[str, Any] = field(default_factory=dict)
    arch: str | None = None

    def build(self, ckpt: Checkpoint, config: SemAttNetConfig | None = None, source: str | None = None) -> nn.Module:
        return builder.build_model_with_weights(ckpt, config=config, arch=self.arch, overrides=self.overrides,
                                                device=self.device, source=source)  # fmt: skip


def from_pretrained(
    name_or_path_or_url: str | os.PathLike[str] | PretrainedWeights,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    map_location: str | torch.device | None = None,
    progress: bool = True,
    arch: str | None = None,
    **overrides: Any,
) -> nn.Module:
    """A model with released or saved weights, in eval mode.

    Every source ends in :func:`semattnet.weights.builder.build_model_with_weights` (config from
    the weights, then ``overrides``, then a strict load).

    Args:
        name_or_path_or_url: one of

            * a registry name (:func:`~semattnet.weights.list_pretrained`, e.g. ``"semattnet-kitti"``) or
              a :class:`~semattnet.weights.PretrainedWeights` record;
            * a local file: the authors' ``.pth.tar``, a torch checkpoint or state dict of this
              library, or ``.safetensors``;
            * a local folder written by :func:`save_pretrained` (``config.json`` + ``model.safetensors``);
            * a URL: ``http(s)://``, ``file://``, ``gdrive://<id>`` (a file), or
              ``hf://owner/repo[@revision]`` (a saved folder on the Hugging Face Hub) /
              ``hf://owner/repo[@revision]/file``.
        sha256: expected sha256 of the downloaded file (for ``hf://owner/repo``: of its
            ``model.safetensors``); see :func:`~semattnet.weights.fetch` for pinning.
        cache_dir: cache root (default ``$SEMATTNET_CACHE``, else the user cache folder).
        map_location: device to put the model on (default CPU).
        progress: show download progress.
        arch: a model name the weights must be for (full model vs backbone), e.g. a torch.hub entry point.
        **overrides: config fields to change that do not change the weights' shapes, e.g.
            ``refinement_mode="clean"``; a shape field (e.g. ``width``) that contradicts the weights
            is a :class:`~semattnet.weights.builder.WeightsMismatchError`.

    Returns:
        The model (:class:`~semattnet.SemAttNet` or :class:`~semattnet.SemAttNetBackbone`), in eval mode.

    Raises:
        UnsafeCheckpointError: a pickle that would run code (it is removed from the cache).
        CheckpointError: not a readable checkpoint, or weights that do not fit.
        semattnet.weights.DownloadError: see :func:`~semattnet.weights.fetch`.
    """
    src = name_or_path_or_url
    load = _Load(sha256, cache_dir, map_location if map_location is not None else "cpu", progress, overrides, arch)
    if isinstance(src, PretrainedWeights):
        return _from_entry(src, load)
    if isinstance(src, os.PathLike) or (isinstance(src, str) and not is_url(src) and Path(src).exists()):
        path = Path(src)
        return _from_folder(path, load) if path.is_dir() else load.build(load_checkpoint(path))
    if not isinstance(src, str):
        raise InputError(f"from_pretrained: expected a name, path or URL, got {type(src).__name__}")
    if is_url(src):
        return _from_url(src, load)
    if src in list_pretrained():
        return _from_entry(get_weights(src), load)
    raise InputError(f"{src!r} is not a known weights name ({', '.join(list_pretrained())}), an existing file or "
                     "folder, or a URL (http(s)://, file://, gdrive://<id>, hf://owner/repo)")  # fmt: skip


def load_model(path: str | os.PathLike[str], device: str | torch.device = "cpu", **overrides: Any) -> nn.Module:
    """The model of a weights file, a ``save_pretrained`` folder or a registry name, in eval mode.

    :func:`from_pretrained` under its older name: the config recorded with the weights (else inferred
    from their shapes), then ``overrides``, which may change only fields that keep the shapes (e.g.
    ``refinement_mode="clean"``), then a strict load.
    """
    return from_pretrained(path, map_location=device, progress=False, **overrides)


def _from_url(src: str, load: _Load) -> nn.Module:
    """A model from ``hf://`` (a saved folder or one file) or a downloaded file URL."""
    if url_scheme(src) == "hf":
        patterns = [CONFIG_NAME, WEIGHTS_NAME, "*.md"]
        path = fetch_hf(src, sha256=load.sha256, cache_dir=load.cache_dir, allow_patterns=patterns)
        return _from_folder(path, load) if path.is_dir() else load.build(load_checkpoint(path))
    root = get_cache_dir(load.cache_dir).resolve()
    return _from_download(root, weights_target(src, load.sha256, root), None, load)


def _from_entry(entry: PretrainedWeights, load: _Load) -> nn.Module:
    if entry.format == "packed":
        return load.build(load_checkpoint(packed_file(entry, load.sha256)), None, f"weights {entry.name!r}")
    root = get_cache_dir(load.cache_dir).resolve()
    if entry.format == "hf-folder":
        url = next((u for u in entry.urls if url_scheme(u) == "hf"), None)
        if url is None:
            raise InputError(f"weights {entry.name!r}: format 'hf-folder' needs an hf:// URL")
        folder = fetch_hf(url, sha256=load.sha256 or entry.sha256, cache_dir=load.cache_dir)
        return _from_folder(folder, load, entry)
    return _from_download(root, weights_target(entry, load.sha256, root), entry, load)


def packed_file(entry: PretrainedWeights, sha256: str | None = None) -> Path:
    """The shipped file of a ``packed`` record, its sha256 checked (``sha256`` else the record's)."""
    path = shipped_path(entry.file_name)
    expected = sha256 or entry.sha256
    if not path.is_file():
        raise CheckpointError(f"weights {entry.name!r}: {path} is missing from the installed package; reinstall it")
    if expected is not None and sha256_file(path) != expected:
        raise CheckpointError(f"weights {entry.name!r}: {path} does not match its sha256 {expected}; reinstall")
    return path


def _from_download(root: Path, target: Any, entry: PretrainedWeights | None, load: _Load) -> nn.Module:
    path, digest = fetch_target(root, target, load.progress)
    config = entry.model_config() if entry is not None else None
    source = f"weights {entry.name!r}" if entry is not None else None
    if _is_safetensors(path):
        return load.build(_read(root, path), config, source)
    converted = root / "converted" / f"{digest}.safetensors"
    if converted.is_file():
        try:
            verify_cached(root, converted, None, announce=False)
            ckpt = load_checkpoint(converted)
        except (OSError, CheckpointError):
            converted.unlink(missing_ok=True)  # damaged: convert again
        else:
            return load.build(ckpt, config, source)
    with cache_lock(root, cache_key(root, converted)):
        ckpt = _read(root, path)  # the safe unpickler; refuses code, removes the file if refused
        save_safetensors(ckpt, converted)
        origin = f"converted from {cache_key(root, path)}"
        record = pin_record(converted, sha256_file(converted), origin, "converted")
        update_pins(root, cache_key(root, converted), record)
    return load.build(ckpt, config, source)


def _read(root: Path, path: Path) -> Checkpoint:
    """``load_checkpoint`` for a cached download; a file it refuses is removed from the cache."""
    try:
        return load_checkpoint(path)
    except (UnsafeCheckpointError, CheckpointError):
        path.unlink(missing_ok=True)
        update_pins(root, cache_key(root, path), None)
        remove_empty_dirs(path.parent, root)
        raise


def _read_config(folder: Path) -> tuple[str, SemAttNetConfig]:
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
        cfg = MODELS[arch][1].replace(**fields)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: invalid config: {exc}") from exc
    return arch, cfg


def _from_folder(folder: Path, load: _Load, entry: PretrainedWeights | None = None) -> nn.Module:
    """A saved folder: its ``config.json`` (or the registry record it came from) and ``model.safetensors``."""
    weights = folder / WEIGHTS_NAME
    for name in (WEIGHTS_NAME, CONFIG_NAME):  # present but a FIFO / device / folder: never skipped silently
        if (folder / name).exists() and not (folder / name).is_file():
            regular_file(folder / name, name, CheckpointError)
    if not weights.is_file():
        present = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
        raise CheckpointError(f"{folder}: no {WEIGHTS_NAME} (found: {', '.join(present) or 'nothing'})")
    if entry is not None:  # the record is the authority on its weights (checked against the tensors)
        return load.build(load_checkpoint(weights), entry.model_config(), f"weights {entry.name!r}")
    config = _read_config(folder)[1] if (folder / CONFIG_NAME).is_file() else None
    return load.build(load_checkpoint(weights), config)


# ----------------------------------------------------------------------------- saving


def _model_card(arch: str, cfg: SemAttNetConfig, n_params: int, weights: PretrainedWeights | None) -> str:
    license_line = weights.license if weights else "set by the uploader"
    lines = [
        "---",
        "library_name: semattnet",
        "tags: [depth-completion, kitti, lidar, pytorch, safetensors]",
        "---",
        "",
        f"# SemAttNet ({arch})",
        "",
        "Depth completion from RGB, a colour-coded semantic map and sparse LiDAR depth "
        "(Nazir et al., IEEE Access 2022, doi:10.1109/ACCESS.2022.3214316).",
        "",
        f"- parameters: {n_params:,}",
        f"- config: `{json.dumps(cfg.to_dict())}`",
        f"- licence: {license_line}",
    ]
    if weights is not None:
        lines.append(f"- weights: `{weights.name}` ({weights.source or ', '.join(weights.urls)})")
        for split, metrics in weights.paper_metrics.items():
            shown = ", ".join(f"{k} {v}" for k, v in metrics.items())
            lines.append(f"- paper, {split}: {shown}")
    lines += [
        "",
        "## Input",
        "",
        "RGB and semantic colours as float 0..255 (B, 3, H, W); sparse depth in metres (B, 1, H, W), "
        "0 = missing; H and W multiples of 32. Output depth in metres.",
        "",
        "## Use",
        "",
        "```python",
        "import semattnet.weights",
        'model = semattnet.weights.from_pretrained("hf://<owner>/<repo>")  # or this folder\'s path',
        "out = model(rgb, semantic, sparse).depth",
        "```",
        "",
    ]
    return "\n".join(lines)


def save_pretrained(
    model: nn.Module,
    folder: str | os.PathLike[str],
    *,
    config: SemAttNetConfig | None = None,
    weights: PretrainedWeights | str | None = None,
) -> Path:
    """Write ``config.json``, ``model.safetensors`` and ``README.md`` into ``folder``.

    Args:
        model: a SemAttNet model (or anything with its state dict).
        folder: created if missing; files in it are replaced atomically.
        config: the model's config (default ``model.config``, else inferred from the state dict).
        weights: the registry record the weights come from, for the model card (licence, metrics).

    Returns:
        ``folder``.
    """
    folder = Path(folder)
    sd = {k: v.detach().to("cpu") for k, v in model.state_dict().items()}
    cfg = config or getattr(model, "config", None) or config_from_state_dict(sd)
    if not isinstance(cfg, SemAttNetConfig):
        raise InputError(f"save_pretrained: config must be a SemAttNetConfig, got {type(cfg).__name__}")
    entry = get_weights(weights) if isinstance(weights, str) else weights
    arch = arch_for(cfg)
    folder.mkdir(parents=True, exist_ok=True)
    save_safetensors(Checkpoint(path=folder / WEIGHTS_NAME, state_dict=sd, format="state_dict", config=cfg),
                     folder / WEIGHTS_NAME)  # fmt: skip
    meta = {"arch": arch, "library_name": "semattnet", "library_version": library_version(), **cfg.to_dict()}
    with atomic_path(folder / CONFIG_NAME) as tmp:
        tmp.write_text(json.dumps(meta, indent=2) + "\n")
    n_params = sum(p.numel() for p in model.parameters())
    with atomic_path(folder / "README.md") as tmp:
        tmp.write_text(_model_card(arch, cfg, n_params, entry))
    return folder


def push_to_hub(
    model: nn.Module,
    repo_id: str,
    *,
    config: SemAttNetConfig | None = None,
    weights: PretrainedWeights | str | None = None,
    private: bool | None = None,
    token: str | None = None,
    revision: str | None = None,
    commit_message: str = "Upload SemAttNet weights",
) -> Any:
    """Save like :func:`save_pretrained` and upload the folder to the Hugging Face Hub.

    Creates the model repository if needed (``HfApi.create_repo(exist_ok=True)``), then
    ``HfApi.upload_folder``; returns what ``upload_folder`` returns (the commit info).
    """
    if is_offline():
        raise OfflineError("offline mode (SEMATTNET_OFFLINE/HF_HUB_OFFLINE): not uploading")
    HfApi = require("huggingface_hub", "push_to_hub").HfApi
    api = HfApi(token=token)
    api.create_repo(repo_id, repo_type="model", private=private, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="semattnet-push-") as tmp:
        save_pretrained(model, tmp, config=config, weights=weights)
        return api.upload_folder(
            repo_id=repo_id, folder_path=tmp, repo_type="model", revision=revision, commit_message=commit_message
        )


# ----------------------------------------------------------------------------- torch.hub

_LOAD_OPTIONS = ("sha256", "cache_dir", "map_location", "progress")


def hub_model(arch: str, pretrained: bool | str | os.PathLike[str] = False, **kwargs: Any) -> nn.Module:
    """The body of the ``hubconf.py`` entry points; both branches go through the one builder.

    Args:
        arch: registry model name (``"semattnet"`` or ``"semattnet_backbone"``).
        pretrained: False (fresh weights; ``kwargs`` are config fields, e.g. ``width=0.25``), True
            (the default released weights of ``arch``), or a weights name, path or URL; the weights
            must be for ``arch``'s model class (full model vs backbone).
        **kwargs: with weights: ``sha256``, ``cache_dir``, ``map_location``, ``progress`` and config
            fields that keep the shapes (e.g. ``refinement_mode``).
    """
    if pretrained is False or pretrained is None:
        return builder.build_model_with_weights(None, arch=arch, overrides=kwargs)
    options = {k: kwargs.pop(k) for k in _LOAD_OPTIONS if k in kwargs}
    source: Any = default_weights(arch) if pretrained is True else pretrained
    return from_pretrained(source, arch=arch, **options, **kwargs)
