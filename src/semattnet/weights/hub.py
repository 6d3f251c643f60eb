"""``from_pretrained`` / ``save_pretrained`` / ``push_to_hub``: a model from a name, file, folder or URL.

The spec is read by :func:`semattnet.weights.resolve.resolve_weights` (the one parser: names, files,
folders, URLs); every file is read through :func:`semattnet.weights.load_checkpoint`, which never runs
pickled code, and every model is built by :func:`semattnet.weights.builder.build_model_with_weights`.

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
from pathlib import Path

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.extras import require
from semattnet._utils.version import library_version
from semattnet.cache import OfflineError, is_offline
from semattnet.models.config import SemAttNetConfig
from semattnet.models.registry import arch_for
from semattnet.weights import builder
from semattnet.weights.checkpoint import Checkpoint, config_from_state_dict, save_safetensors
from semattnet.weights.pretrained import PretrainedWeights, default_weights, get_weights
from semattnet.weights.resolve import CONFIG_NAME, WEIGHTS_NAME, resolve_weights

__all__ = [
    "CONFIG_NAME",
    "WEIGHTS_NAME",
    "from_pretrained",
    "hub_model",
    "load_model",
    "push_to_hub",
    "save_pretrained",
]


def from_pretrained(
    name_or_path_or_url: str | os.PathLike[str] | PretrainedWeights,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    map_location: str | torch.device | None = None,
    progress: bool = True,
    arch: str | None = None,
    **overrides: object,
) -> nn.Module:
    """A model with released or saved weights, in eval mode.

    The spec goes through :func:`~semattnet.weights.resolve.resolve_weights`, the weights through
    :func:`semattnet.weights.builder.build_model_with_weights` (config from the weights, then
    ``overrides``, then a strict load).

    Args:
        name_or_path_or_url: one of

            * a registry name (:func:`~semattnet.weights.list_pretrained`, e.g. ``"semattnet-kitti"`` or the
              shipped ``"semattnet-demo-ref-seed0"``) or a :class:`~semattnet.weights.PretrainedWeights` record;
            * a local file: the authors' ``.pth.tar``, a torch checkpoint or state dict of this
              library, ``.safetensors`` or packed weights;
            * a local folder written by :func:`save_pretrained` (``config.json`` + ``model.safetensors``);
            * a URL: ``http(s)://``, ``file://``, ``gdrive://<id>`` (a file), or
              ``hf://owner/repo[@revision]`` (a saved folder on the Hugging Face Hub) /
              ``hf://owner/repo[@revision]/file``.
        sha256: expected sha256 of the downloaded file (for ``hf://owner/repo``: of its
            ``model.safetensors``); see :func:`~semattnet.weights.fetch_weights` for pinning.
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
        semattnet.cache.DownloadError: see :func:`~semattnet.weights.fetch_weights`.
    """
    resolved = resolve_weights(name_or_path_or_url, sha256=sha256, cache_dir=cache_dir, progress=progress)
    return resolved.build(arch, overrides, map_location if map_location is not None else "cpu")


def load_model(
    path: str | os.PathLike[str] | PretrainedWeights, device: str | torch.device = "cpu", **overrides: object
) -> nn.Module:
    """Deprecated since 0.2 (goes in 0.3): :func:`from_pretrained` under its older name (the model of a weights
    file, a ``save_pretrained`` folder, a registry name or a URL, in eval mode)."""
    import warnings

    warnings.warn(
        "semattnet.weights.load_model is deprecated since 0.2 and goes in 0.3: use semattnet.from_pretrained",
        DeprecationWarning,
        stacklevel=2,
    )
    return resolve_weights(path, progress=False).build(None, overrides, device)


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
    save_safetensors(
        Checkpoint(path=folder / WEIGHTS_NAME, state_dict=sd, format="state_dict", config=cfg), folder / WEIGHTS_NAME
    )
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
) -> object:
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


def hub_model(arch: str, pretrained: bool | str | os.PathLike[str] = False, **kwargs: object) -> nn.Module:
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
    source = default_weights(arch) if pretrained is True else pretrained
    resolved = resolve_weights(
        source,
        sha256=_text(options, "sha256"),
        cache_dir=_text(options, "cache_dir"),
        progress=options.get("progress") is not False,
    )
    device = options.get("map_location", "cpu")
    if not isinstance(device, str | torch.device):
        raise InputError(f"torch.hub: map_location must be a device name or torch.device, got {device!r}")
    return resolved.build(arch, kwargs, device)


def _text(options: dict[str, object], key: str) -> str | None:
    """A loading option that is a text or a path (``sha256``, ``cache_dir``), or None."""
    value = options.get(key)
    if value is None or isinstance(value, str | os.PathLike):
        return None if value is None else os.fspath(value)
    raise InputError(f"torch.hub: {key} must be a text or a path, got {type(value).__name__}")
