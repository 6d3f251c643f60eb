"""Semantic maps for any frame: run a segmentation network the user supplies.

SemAttNet reads colour-coded maps of a palette (:mod:`semattnet.palette`: Cityscapes trainIds for
street scenes, NYU-40 for indoor ones). The authors only released precomputed maps for KITTI;
:func:`segment_folder` makes them for any image tree with a network given by a SPEC (see :func:`load_segmenter`):

* ``path/to/model.pt`` (or ``.ts``, ``.jit``, ``.torchscript``): a TorchScript module;
* ``path/to/model.onnx``: an ONNX graph, run with onnxruntime (``pip install onnxruntime``);
* ``torchvision:ARCH:WEIGHTS``: a torchvision segmentation architecture (e.g.
  ``deeplabv3_resnet50``) with a state-dict file (``pip install torchvision``);
* ``hf:ORG/NAME``, ``hf:PATH``, ``hf:default`` or ``hf:indoor``: a SegFormer / Mask2Former ...
  through ``transformers`` (``pip install 'semattnet[segment]'``), its classes matched to the palette's
  by name (:mod:`semattnet.segmentation.hf`; ``hf:default`` is SegFormer-B5 on Cityscapes, ``hf:indoor``
  SegFormer-B5 on ADE20K mapped to NYU-40, both downloaded from the Hugging Face Hub);
* ``unknown``: no network, every pixel gets :data:`~semattnet.palette.UNKNOWN_COLOR` (the
  fallback for frames without a segmenter; expect worse depth, see the README).

The network takes (B, 3, H, W) float32 RGB, scaled to [0, 1] then normalised with ``mean`` /
``std`` (ImageNet's by default, what torchvision and most Cityscapes models expect), and returns
logits (B, C, h, w) (a tensor, a tuple whose first item is one, or a dict with ``"out"``) with
C = 19 (trainIds) or 34 (Cityscapes labelIds), or already-decided (B, h, w) integer trainIds; for the
``nyu40`` palette C = 40 (ids 1..40) or 41 (0 = unlabelled first), or integer ids 0..40.
Logits are resized bilinearly to the image size before the arg-max. Only ``hf:`` specs download.
"""

from __future__ import annotations

import os
import pickle
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from semattnet._errors import DataError, InputError
from semattnet._utils.device import resolve_device
from semattnet._utils.extras import require
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs
from semattnet._utils.progress import progress as progress_bar
from semattnet.data.io import read_image, write_image
from semattnet.palette import IGNORE_ID, NUM_CLASSES, ids_to_colors, label_ids_to_train_ids

__all__ = [
    "IMAGENET_MEAN",
    "IMAGENET_STD",
    "IMAGE_SUFFIXES",
    "SegmentSummary",
    "Segmenter",
    "load_segmenter",
    "segment_folder",
]

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
_TORCHSCRIPT_SUFFIXES = (".pt", ".pth", ".ts", ".jit", ".torchscript")
NYU40 = 40  # classes of the nyu40 palette

#: A segmentation network: normalised (B, 3, H, W) RGB -> logits or class ids (a tensor or array, or a
#: dict with ``"out"`` or a tuple / list whose first item is one), checked by :class:`Segmenter`.
Network = Callable[[torch.Tensor], object]


class Segmenter:
    """(B, H, W, 3) uint8 RGB images -> (B, H, W) uint8 ids of ``palette`` (255 = unknown): Cityscapes trainIds,
    or NYU-40 ids 1..40 (0 = unlabelled).

    Args:
        network: maps a normalised (B, 3, h, w) float32 tensor on ``device`` to the network's
            output (module docstring); ``None`` is the no-segmenter fallback.
        name: shown in error messages (the SPEC).
        mean: per-channel mean subtracted after scaling to [0, 1].
        std: per-channel standard deviation divided by after subtracting ``mean``.
        input_size: run the network at this (h, w) (bilinear resize) instead of the image size.
        palette: what the network's classes are: ``cityscapes`` (19 trainIds or 34 labelIds) or ``nyu40``
            (40 classes, ids 1..40 in order; or 41 with 0 = unlabelled first).
    """

    def __init__(
        self,
        network: Network | None,
        name: str,
        device: torch.device | str = "cpu",
        mean: Sequence[float] = IMAGENET_MEAN,
        std: Sequence[float] = IMAGENET_STD,
        input_size: tuple[int, int] | None = None,
        palette: str = "cityscapes",
    ) -> None:
        from semattnet.palette import get_palette

        self.network, self.name, self.palette = network, name, get_palette(palette).name
        self.device = torch.device(device)
        self.mean = torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1)
        self.std = torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1)
        self.input_size = input_size

    def __call__(self, images: np.ndarray) -> np.ndarray:
        images = np.asarray(images)
        if images.ndim != 4 or images.shape[-1] != 3:
            raise InputError(f"{self.name}: expected (B, H, W, 3) images, got {images.shape}")
        b, h, w = images.shape[:3]
        if self.network is None:
            return np.full((b, h, w), IGNORE_ID, dtype=np.uint8)
        x = torch.from_numpy(np.ascontiguousarray(images)).permute(0, 3, 1, 2).float() / 255.0
        x = ((x - self.mean) / self.std).to(self.device)
        if self.input_size is not None and tuple(self.input_size) != (h, w):
            x = F.interpolate(x, size=self.input_size, mode="bilinear", align_corners=False)
        with torch.inference_mode():
            out = self.network(x)
        return self._to_ids(out, (h, w))

    def _to_ids(self, raw: object, size: tuple[int, int]) -> np.ndarray:
        if isinstance(raw, dict):
            raw = raw["out"]
        elif isinstance(raw, (tuple, list)):
            raw = raw[0]
        out = torch.as_tensor(raw)
        top = NUM_CLASSES - 1 if self.palette == "cityscapes" else NYU40
        if not out.is_floating_point():  # already class ids
            ids = out if out.dim() == 4 else out[:, None]
            ids = F.interpolate(ids.float(), size=size, mode="nearest").long()[:, 0]
            bad = (ids != IGNORE_ID) & ((ids < 0) | (ids > top))
            if bool(bad.any()):
                raise DataError(f"{self.name}: returned class ids outside 0..{top} and {IGNORE_ID}")
            return ids.to(torch.uint8).cpu().numpy()
        if self.palette == "nyu40":
            return self._nyu40_ids(out, size)
        if out.dim() != 4:
            raise DataError(f"{self.name}: expected (B, C, H, W) logits, got shape {tuple(out.shape)}")
        classes = out.shape[1]
        if classes not in (NUM_CLASSES, 34):
            raise DataError(
                f"{self.name}: returned {classes} classes; expected 19 (Cityscapes trainIds) or 34 (labelIds)"
            )
        ids = F.interpolate(out.float(), size=size, mode="bilinear", align_corners=False).argmax(dim=1)
        ids_np = ids.cpu().numpy()
        return label_ids_to_train_ids(ids_np) if classes == 34 else ids_np.astype(np.uint8)

    def _nyu40_ids(self, out: torch.Tensor, size: tuple[int, int]) -> np.ndarray:
        if out.dim() != 4 or out.shape[1] not in (NYU40, NYU40 + 1):
            raise DataError(
                f"{self.name}: expected (B, 40, H, W) NYU-40 scores (or 41 with unlabelled first), got "
                f"shape {tuple(out.shape)}"
            )
        ids = F.interpolate(out.float(), size=size, mode="bilinear", align_corners=False).argmax(dim=1)
        return (ids + (1 if out.shape[1] == NYU40 else 0)).to(torch.uint8).cpu().numpy()


def _torchscript(path: Path, device: torch.device) -> Network:
    try:
        module = torch.jit.load(str(path), map_location=device)
    except Exception as err:
        raise DataError(f"{path}: not a loadable TorchScript file ({type(err).__name__})") from None
    return module.eval()


def _onnx(path: Path, device: torch.device) -> Network:
    ort = require("onnxruntime", f"{path}: ONNX segmenters")
    providers = ["CPUExecutionProvider"]
    if device.type == "cuda" and "CUDAExecutionProvider" in ort.get_available_providers():
        providers.insert(0, "CUDAExecutionProvider")
    try:
        session = ort.InferenceSession(str(path), providers=providers)
    except Exception as err:
        raise DataError(f"{path}: not a loadable ONNX model ({err})") from None
    name = session.get_inputs()[0].name

    def run(x: torch.Tensor) -> torch.Tensor:
        return torch.from_numpy(session.run(None, {name: x.cpu().numpy()})[0])

    return run


def _torchvision(arch: str, weights: Path, device: torch.device) -> Network:
    segmentation = require("torchvision.models.segmentation", "torchvision segmenters")
    ctor = getattr(segmentation, arch, None)
    if ctor is None or arch.startswith("_"):
        raise InputError(f"torchvision.models.segmentation has no architecture {arch!r}")
    try:  # weights_only: a pickle that names code is refused (pickle.UnpicklingError), never run
        state = torch.load(str(weights), map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError) as err:
        first = (str(err).strip().splitlines() or [type(err).__name__])[0]
        raise DataError(f"{weights}: not a loadable (weights-only) PyTorch state dict: {first}") from None
    for key in ("model", "state_dict"):
        if isinstance(state, dict) and isinstance(state.get(key), dict):
            state = state[key]
    if not isinstance(state, dict):
        raise DataError(f"{weights}: expected a state dict")
    head = [k for k in state if k.startswith("classifier.") and k.endswith("weight")]
    classes = int(state[sorted(head)[-1]].shape[0]) if head else NUM_CLASSES
    aux = any(k.startswith("aux_classifier.") for k in state)
    net = ctor(weights=None, weights_backbone=None, num_classes=classes, aux_loss=aux)
    try:
        net.load_state_dict(state)
    except RuntimeError as err:  # torch lists the missing / unexpected keys over several lines
        detail = re.sub(r"^Error\(s\) in loading state_dict for \S+:\s*", "", " ".join(str(err).split()))
        raise DataError(f"{weights}: does not fit torchvision's {arch}: {detail[:300]}") from None
    return net.to(device).eval()


def _check_normalisation(mean: Sequence[float], std: Sequence[float]) -> None:
    for name, vals in (("--mean", mean), ("--std", std)):
        v = np.asarray(vals, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise InputError(f"{name}: expected three finite numbers R,G,B; got {list(vals)}")
    if not all(float(x) > 0 for x in std):
        raise InputError(f"--std: every value must be positive (the image is divided by it); got {list(std)}")


def load_segmenter(
    spec: str,
    device: str | torch.device = "auto",
    mean: Sequence[float] = IMAGENET_MEAN,
    std: Sequence[float] = IMAGENET_STD,
    input_size: tuple[int, int] | None = None,
    palette: str | None = None,
) -> Segmenter:
    """Build a :class:`Segmenter` from a SPEC (module docstring) whose ids are of ``palette`` (None: the spec's
    own, :func:`~semattnet.segmentation.hf.hf_palette` for ``hf:``, else ``cityscapes``; an ``hf:`` model's
    classes are matched to the palette's by name).

    Raises:
        InputError: ``mean`` / ``std`` not three finite numbers, a ``std`` that is not positive (a division
            by zero), a bad device.
    """
    _check_normalisation(mean, std)
    dev = resolve_device(device)
    if spec == "unknown":
        return Segmenter(None, spec, dev, palette=palette or "cityscapes")
    if spec.startswith("hf:"):
        from semattnet.segmentation.hf import hf_palette, load_hf_network

        pal = palette or hf_palette(spec[3:])
        return Segmenter(load_hf_network(spec[3:], dev, pal), spec, dev, mean, std, input_size, pal)
    pal = palette or "cityscapes"
    if spec.startswith("torchvision:"):
        parts = spec.split(":", 2)
        if len(parts) != 3 or not parts[1] or not parts[2]:
            raise InputError(f"{spec!r}: expected torchvision:ARCH:WEIGHTS, e.g. torchvision:deeplabv3_resnet50:w.pth")
        weights = Path(parts[2])
        if not weights.is_file():
            raise DataError(f"{weights}: no such weights file")
        return Segmenter(_torchvision(parts[1], weights, dev), spec, dev, mean, std, input_size, pal)
    path = Path(spec)
    if not path.is_file():
        raise DataError(
            f"{spec}: no such model file (expected .onnx, TorchScript, torchvision:ARCH:WEIGHTS, hf:... or unknown)"
        )
    if path.suffix.lower() == ".onnx":
        return Segmenter(_onnx(path, dev), spec, dev, mean, std, input_size, pal)
    if path.suffix.lower() in _TORCHSCRIPT_SUFFIXES:
        return Segmenter(_torchscript(path, dev), spec, dev, mean, std, input_size, pal)
    raise DataError(
        f"{spec}: unknown model format {path.suffix!r} (expected .onnx or {', '.join(_TORCHSCRIPT_SUFFIXES)})"
    )


@dataclass
class SegmentSummary:
    written: int
    skipped: int  # already there from an earlier run
    total: int


def _images(root: Path, exclude: Path) -> list[Path]:
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and (here / d).resolve() != exclude)
        found += [here / f for f in sorted(filenames) if f.lower().endswith(IMAGE_SUFFIXES) and not f.startswith(".")]
    return found


def _batches(
    items: Iterable[tuple[Path, Path, np.ndarray]], size: int
) -> Iterator[list[tuple[Path, Path, np.ndarray]]]:
    batch: list[tuple[Path, Path, np.ndarray]] = []
    for item in items:
        if batch and (len(batch) == size or item[2].shape != batch[0][2].shape):
            yield batch
            batch = []
        batch.append(item)
    if batch:
        yield batch


def segment_folder(
    segmenter: Segmenter,
    images: str | Path,
    out: str | Path,
    batch_size: int = 4,
    overwrite: bool = False,
    progress: bool = True,
) -> SegmentSummary:
    """Write a colour-coded map for every image under ``images`` into the mirrored path under ``out``.

    ``kitti_raw/<date>/<drive>/image_02/data/<frame>.png`` becomes
    ``out/<date>/<drive>/image_02/data/<frame>.png``: pass the raw root and the semantic root
    the KITTI loader reads. Finished maps are skipped, so an interrupted run resumes where it
    stopped (each map is written atomically: a map on disk is complete). Images of one size are
    batched together.
    """
    images, out = Path(images), Path(out)
    if not images.is_dir():
        raise DataError(f"{images}: not a folder of images")
    if batch_size < 1:
        raise InputError(f"batch_size must be at least 1, got {batch_size}")
    files = _images(images, out.resolve())
    if not files:
        raise DataError(f"{images}: no {'/'.join(IMAGE_SUFFIXES)} images found")
    targets = [out / f.relative_to(images).with_suffix(".png") for f in files]
    check_no_input_overlap(files, out_files=targets)  # --out == --images would replace PNG images
    model = [("--model", Path(segmenter.name))] if Path(segmenter.name).is_file() else []
    replaced = [Output("--out", t, "png") for t in targets if overwrite and t.exists()]  # only maps of ours
    check_outputs([("--images", images), *model], [Output("--out", out, "folder"), *replaced], overwrite)
    todo = [(f, t) for f, t in zip(files, targets, strict=True) if overwrite or not t.exists()]
    written = 0
    with progress_bar(
        total=len(files),
        initial=len(files) - len(todo),
        desc="segmenting",
        unit="image",
        enabled=progress,
        dynamic_ncols=True,
    ) as bar:
        for batch in _batches(((f, t, read_image(f)) for f, t in todo), batch_size):
            ids = segmenter(np.stack([img for _, _, img in batch]))
            for (_, target, _), m in zip(batch, ids, strict=True):
                write_image(target, ids_to_colors(m, segmenter.palette), overwrite=overwrite)
            written += len(batch)
            bar.update(len(batch))
    return SegmentSummary(written=written, skipped=len(files) - len(todo), total=len(files))
