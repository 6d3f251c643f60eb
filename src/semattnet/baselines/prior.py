"""A monocular depth prior fitted to the sparse points: ``--method prior --prior hf:ORG/NAME``.

A monocular network (Depth Anything V2 and the other models ``transformers``' ``AutoModelForDepthEstimation``
reads, ``pip install 'semattnet[segment]'``) predicts depth from the image alone, up to an unknown scale (and,
for the relative models, a shift in inverse depth). The frame's own sparse points fix them, the way Prior Depth
Anything and OMNI-DC v1.1 put such a prior on a metric scale:

- a *relative* model (``config.depth_estimation_type == "relative"``, Depth Anything's default, and the
  MiDaS-style DPT models) predicts a disparity ``r`` affine in inverse depth: ``1 / D = s r + t``;
- a *metric* model (``"metric"``: Depth Anything V2 Metric, ZoeDepth, GLPN) predicts depth up to the camera it
  was trained for: ``D = s r``.

``s`` and ``t`` are least squares over the points, refitted twice without the points whose residual is over
:data:`OUTLIER_MADS` median absolute deviations (a LiDAR return seen through glass, a mixed edge). The result is
clamped to the points' own depth range, as the classical completion's is. No learned part of semattnet runs:
this is a baseline beside ``--method classical``, for a rig where such a model is available; its benefit was
not measured here (no weights can be downloaded in this project's sessions; the tests run a tiny random model).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from semattnet._errors import DataError, InputError
from semattnet._utils.extras import require
from semattnet.inference.contract import Completion
from semattnet.models.checks import check_has_points

__all__ = ["OUTLIER_MADS", "PriorCompleter", "fit_prior", "load_prior"]

#: A point whose residual is over this many median absolute deviations is left out of the refit.
OUTLIER_MADS = 4.0
#: The refits without outliers.
_REFITS = 2

#: A monocular network: (H, W, 3) uint8 RGB -> (H, W) float32 prediction at the image's size.
PriorNetwork = Callable[[np.ndarray], np.ndarray]


def _solve(x: np.ndarray, y: np.ndarray, affine: bool) -> tuple[float, float]:
    """Least squares ``y ~ s x + t`` (``affine``) or ``y ~ s x``."""
    if affine:
        a = np.stack([x, np.ones_like(x)], axis=1)
        (s, t), *_ = np.linalg.lstsq(a, y, rcond=None)
        return float(s), float(t)
    return float(np.dot(x, y) / max(float(np.dot(x, x)), 1e-30)), 0.0


def fit_prior(prediction: np.ndarray, sparse: np.ndarray, relative: bool = True) -> tuple[float, float]:
    """``(s, t)`` that put ``prediction`` (H, W) on the metric scale of ``sparse`` (H, W metres, 0 = none): for a
    relative prediction ``1 / D = s r + t``, for a metric one ``D = s r`` (``t = 0``); least squares over the
    points, refitted without outliers (module doc).

    Raises:
        DataError: fewer than two points, or a prediction that does not vary over them (nothing to fit).
    """
    valid = (sparse > 0) & np.isfinite(prediction)
    if int(valid.sum()) < 2:
        raise DataError(f"the prior needs at least 2 sparse points to fit its scale, got {int(valid.sum())}")
    x = prediction[valid].astype(np.float64)
    z = sparse[valid].astype(np.float64)
    y = 1.0 / z if relative else z
    if relative and float(np.ptp(x)) <= 1e-12:
        raise DataError("the prior's prediction is the same at every sparse point: its scale cannot be fitted")
    s, t = _solve(x, y, relative)
    for _ in range(_REFITS):
        residual = np.abs(s * x + t - y)
        mad = float(np.median(np.abs(residual - np.median(residual))))
        keep = residual <= np.median(residual) + OUTLIER_MADS * max(mad, 1e-12)
        if keep.sum() < 2:
            break
        s, t = _solve(x[keep], y[keep], relative)
    return s, t


@dataclass
class PriorCompleter:
    """A monocular ``network`` (:data:`PriorNetwork`) fitted to each frame's points (:func:`fit_prior`) behind the
    completer call: ``completer(rgb, sparse, semantic=None)`` -> ``Completion`` (no uncertainty; the semantic map
    is unused). ``relative``: the network predicts relative inverse depth (else metric depth)."""

    network: PriorNetwork
    relative: bool = True
    device: str = "cpu"
    needs_semantic = False
    gives_uncertainty = False
    palette = "cityscapes"  # unused: it reads no semantic map

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        sparse = np.asarray(sparse, np.float32)
        check_has_points(torch.from_numpy(sparse))
        prediction = np.asarray(self.network(np.asarray(rgb)), np.float64)
        if prediction.shape != sparse.shape:
            raise InputError(f"the prior predicted {prediction.shape}, the frame is {sparse.shape}")
        s, t = fit_prior(prediction, sparse, self.relative)
        if self.relative:
            inverse = s * prediction + t
            depth = np.where(inverse > 0, 1.0 / np.maximum(inverse, 1e-12), np.inf)
        else:
            depth = s * prediction
        points = sparse[sparse > 0]
        depth = np.clip(np.nan_to_num(depth, nan=float(points.max())), float(points.min()), float(points.max()))
        return Completion(depth=depth.astype(np.float32))


def load_prior(spec: str, device: str = "cpu") -> PriorCompleter:
    """The completer of ``hf:ORG/NAME[@REVISION]`` or ``hf:PATH`` (a folder written by ``save_pretrained``):
    ``transformers``' ``AutoModelForDepthEstimation`` and its image processor, the prediction resized to the
    image (bilinear), relative or metric as its config says (module doc).

    Raises:
        InputError: ``spec`` is not ``hf:...``. MissingDependencyError: transformers is not installed.
        DataError: the model cannot be loaded.
    """
    from semattnet.segmentation.hf import resolve_hf_source

    if not spec.startswith("hf:"):
        raise InputError(f"--prior {spec!r}: expected hf:ORG/NAME or hf:PATH (a transformers depth model)")
    source, revision = resolve_hf_source(spec[3:])
    transformers = require("transformers", "the monocular prior (--method prior)")
    try:
        processor = transformers.AutoImageProcessor.from_pretrained(source, revision=revision)
        model = transformers.AutoModelForDepthEstimation.from_pretrained(source, revision=revision)
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(f"--prior {spec}: cannot load a depth model ({type(exc).__name__}: {exc})") from None
    model = model.to(device).eval()
    relative = getattr(model.config, "depth_estimation_type", "relative") != "metric"

    def network(rgb: np.ndarray) -> np.ndarray:
        inputs = processor(images=rgb, return_tensors="pt")
        with torch.inference_mode():
            out = model(pixel_values=inputs["pixel_values"].to(device)).predicted_depth
        full = F.interpolate(out[:, None].float(), size=rgb.shape[:2], mode="bilinear", align_corners=False)
        return full[0, 0].cpu().numpy()

    return PriorCompleter(network, relative, str(device))
