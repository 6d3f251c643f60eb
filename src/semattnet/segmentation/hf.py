"""Segmenters from the Hugging Face Hub (``hf:`` specs of :func:`~semattnet.segmentation.load_segmenter`).

``hf:ORG/NAME[@REVISION]`` loads a semantic-segmentation model with ``transformers``
(``pip install 'semattnet[segment]'``): SegFormer, UperNet, DPT, BEiT ... (anything
``AutoModelForSemanticSegmentation`` reads, whose output has ``logits``) or Mask2Former / MaskFormer
(``AutoModelForUniversalSegmentation``; per-class maps are the query class probabilities times the
query masks). ``hf:PATH`` reads a local folder written by ``save_pretrained``; ``hf:default`` (street scenes,
Cityscapes) and ``hf:indoor`` (ADE20K, maps in NYU-40) are :data:`HF_SEGMENTERS` entries.

For the Cityscapes palette the model's classes are matched to the 19 trainIds by the names in its config's
``id2label``, ignoring case, spaces, ``_`` and ``-``, plural ``s`` and common variants ("motorbike",
"pedestrian", "on rails" ...); for the NYU-40 palette, by :mod:`semattnet.segmentation.indoor`. Classes of
neither are dropped; palette classes the model does not know are never predicted.
``SEMATTNET_OFFLINE=1`` / ``HF_HUB_OFFLINE=1``: only the local Hugging Face cache is used.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import torch

from semattnet._errors import DataError, InputError
from semattnet._utils.extras import require
from semattnet.palette import NUM_CLASSES, TRAIN_CLASSES

__all__ = [
    "HF_SEGMENTERS",
    "HFSegmenterRecord",
    "cityscapes_indices",
    "hf_palette",
    "load_hf_network",
    "resolve_hf_source",
]


@dataclass(frozen=True)
class HFSegmenterRecord:
    """A recommended segmenter on the Hugging Face Hub: ``val_miou`` on ``benchmark``; its maps in ``palette``."""

    repo: str
    description: str
    license: str
    val_miou: float
    metric_source: str
    palette: str = "cityscapes"
    benchmark: str = "Cityscapes val"

    @property
    def cityscapes_val_miou(self) -> float | None:
        """``val_miou`` when the benchmark is Cityscapes val (the default record's number)."""
        return self.val_miou if self.benchmark == "Cityscapes val" else None


#: ``hf:<key>`` shortcuts.
HF_SEGMENTERS: Mapping[str, HFSegmenterRecord] = {
    "default": HFSegmenterRecord(
        repo="nvidia/segformer-b5-finetuned-cityscapes-1024-1024",
        description="SegFormer-B5 (MiT-B5 encoder, all-MLP decoder) fine-tuned on Cityscapes at 1024x1024",
        license=(
            "'other' on the model card: NVIDIA's SegFormer licence (NVIDIA Source Code License, research and "
            "non-commercial use only); see the model card before using the maps commercially"
        ),
        val_miou=82.4,
        metric_source=(
            "SegFormer paper (Xie et al., NeurIPS 2021, arXiv:2105.15203): B5 at 1024x1024, single-scale "
            "Cityscapes val mIoU 82.4 %; 84.0 % with multi-scale and flip testing (the abstract's number)"
        ),
    ),
    "indoor": HFSegmenterRecord(
        repo="nvidia/segformer-b5-finetuned-ade-640-640",
        description="SegFormer-B5 fine-tuned on ADE20K (150 classes) at 640x640; its classes mapped to NYU-40 by "
        "name (semattnet.segmentation.indoor)",
        license="'other' on the model card: NVIDIA's SegFormer licence (research and non-commercial use only)",
        val_miou=51.0,
        metric_source="SegFormer paper (Xie et al., NeurIPS 2021, arXiv:2105.15203), Table 2: B5, ADE20K val "
        "single-scale mIoU 51.0 % (51.8 % multi-scale); not a NYU-40 score",
        palette="nyu40",
        benchmark="ADE20K val",
    ),
}

# normalised name -> Cityscapes class name, for variants seen in model configs
_VARIANTS = {
    "pavement": "sidewalk",
    "trafficsignal": "traffic light",
    "pedestrian": "person",
    "people": "person",
    "human": "person",
    "motorbike": "motorcycle",
    "bike": "bicycle",
    "onrails": "train",
    "tram": "train",
    "vehicle": "car",
    "vegetations": "vegetation",
}


def _norm(name: str) -> str:
    return re.sub(r"[^a-z]", "", str(name).lower())


_CITYSCAPES = {_norm(name): t for t, (name, _) in enumerate(TRAIN_CLASSES)}


def _train_id(label: str) -> int | None:
    key = _norm(label)
    for k in (key, _norm(_VARIANTS.get(key, "")), key[:-1] if key.endswith("s") else ""):
        if k in _CITYSCAPES:
            return _CITYSCAPES[k]
    return None


def cityscapes_indices(id2label: Mapping[int, str] | Mapping[str, str]) -> list[list[int]]:
    """For each trainId 0..18, the model class indices whose names mean it (often one, maybe none)."""
    found: list[list[int]] = [[] for _ in range(NUM_CLASSES)]
    for idx, label in sorted((int(k), v) for k, v in id2label.items()):
        t = _train_id(label)
        if t is not None:
            found[t].append(idx)
    return found


def resolve_hf_source(rest: str) -> tuple[str, str | None]:
    """``default`` / ``ORG/NAME[@REV]`` / local folder -> (repo id or folder, revision)."""
    if rest in HF_SEGMENTERS:
        return HF_SEGMENTERS[rest].repo, None
    if not rest:
        raise InputError("hf: expected hf:ORG/NAME, hf:PATH or hf:default")
    if Path(rest).expanduser().is_dir():
        return str(Path(rest).expanduser()), None
    repo, _, rev = rest.partition("@")
    if not re.fullmatch(r"[\w.-]+/[\w.-]+", repo):
        raise InputError(f"hf:{rest}: not a local folder nor a Hub id ORG/NAME[@REVISION]")
    return repo, rev or None


class _LabelledConfig(Protocol):
    id2label: Mapping[int, str]


@runtime_checkable
class _MaskOutput(Protocol):
    """A universal (mask classification) model's output: Mask2Former, MaskFormer, OneFormer."""

    class_queries_logits: torch.Tensor
    masks_queries_logits: torch.Tensor


class _SemanticOutput(Protocol):
    """A semantic segmentation model's output (SegFormer, ...)."""

    logits: torch.Tensor


class _HFModel(Protocol):
    """The part of a ``transformers`` segmentation model that :func:`load_hf_network` uses."""

    config: _LabelledConfig

    def to(self, device: torch.device | str) -> _HFModel: ...

    def eval(self) -> _HFModel: ...

    def __call__(self, *, pixel_values: torch.Tensor) -> _MaskOutput | _SemanticOutput: ...


def _load_model(source: str, revision: str | None) -> _HFModel:
    transformers = require("transformers", "hf: segmenters")
    from semattnet.cache import is_offline

    kw = {"revision": revision, "local_files_only": is_offline()}
    try:
        config = transformers.AutoConfig.from_pretrained(source, **kw)
        universal = config.model_type in ("mask2former", "maskformer", "oneformer")
        kind = "Universal" if universal else "Semantic"
        auto = getattr(transformers, f"AutoModelFor{kind}Segmentation")
        if int(transformers.__version__.split(".")[0]) >= 5:  # else 5.x wants the `kernels` package by default
            kw["use_kernels"] = False
        return auto.from_pretrained(source, **kw)
    except (OSError, ValueError, KeyError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        offline = " (offline mode: only the local Hugging Face cache is used)" if is_offline() else ""
        raise DataError(f"hf:{source}: cannot load the model{offline}: {first}") from None


def _class_maps(out: _MaskOutput | _SemanticOutput) -> torch.Tensor:
    """(B, C, h, w) per-class scores from a semantic or a universal (mask classification) output."""
    if isinstance(out, _MaskOutput):
        probs = out.class_queries_logits.softmax(-1)[..., :-1]  # the last class is "no object"
        return torch.einsum("bqc,bqhw->bchw", probs, out.masks_queries_logits.sigmoid())
    return out.logits


def hf_palette(rest: str) -> str:
    """The palette ``hf:<rest>`` writes by default: its :data:`HF_SEGMENTERS` record's, else ``cityscapes``."""
    return HF_SEGMENTERS[rest].palette if rest in HF_SEGMENTERS else "cityscapes"


def _groups(rest: str, id2label: Mapping[int, str] | Mapping[str, str], palette: str) -> list[list[int]]:
    """Per palette class, the model classes that mean it; warns of the classes none means."""
    from semattnet.palette import get_palette
    from semattnet.segmentation.indoor import nyu40_indices

    pal = get_palette(palette)
    groups = nyu40_indices(id2label) if pal.name == "nyu40" else cityscapes_indices(id2label)
    if not any(groups):
        labels = ", ".join(list(id2label.values())[:8])
        raise DataError(f"hf:{rest}: none of its labels ({labels}, ...) is a {pal.title} class")
    missing = [pal.classes[t][0] for t, g in enumerate(groups) if not g]
    if missing:
        warnings.warn(f"hf:{rest}: no class for {', '.join(missing)}; those are never predicted", stacklevel=3)
    return groups


def load_hf_network(
    rest: str, device: torch.device | str = "cpu", palette: str | None = None
) -> Callable[[torch.Tensor], torch.Tensor]:
    """The network of ``hf:<rest>``: normalised (B, 3, H, W) RGB -> (B, C, h, w) scores of ``palette``'s
    classes (None: :func:`hf_palette`): C = 19 Cityscapes trainIds, or 40 NYU-40 ids 1..40 in order.

    Raises:
        MissingDependencyError: transformers is not installed.
        DataError: the model cannot be loaded, or none of its labels is a class of the palette.
    """
    source, revision = resolve_hf_source(rest)
    model = _load_model(source, revision).to(device).eval()
    groups = _groups(rest, model.config.id2label, palette or hf_palette(rest))

    def run(x: torch.Tensor) -> torch.Tensor:
        scores = _class_maps(model(pixel_values=x))
        floor = torch.full_like(scores[:, 0], torch.finfo(scores.dtype).min)
        return torch.stack([scores[:, g].amax(1) if g else floor for g in groups], dim=1)

    return run
