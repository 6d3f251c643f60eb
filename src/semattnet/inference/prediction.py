"""What every output sink receives: one completed frame as :class:`Prediction`, made once per frame by
:func:`predict_frame` (the one hole / clamp rule and the one quantisation; :mod:`semattnet.inference.sinks`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from semattnet._errors import InputError
from semattnet.data.frames import Frame
from semattnet.data.io import PNG_COMPRESS_LEVEL, clamp_for_png, decode_depth, encode_depth
from semattnet.inference.completer import Completion
from semattnet.inference.uncertainty import UncertaintyLimit, clean_uncertainty, encode_uncertainty
from semattnet.models.outputs import DepthCompletionOutput

if TYPE_CHECKING:  # geometry's point clouds are imported where used
    from semattnet.geometry import PointCloud

__all__ = ["Prediction", "fusion_confidence", "predict_frame"]


def fusion_confidence(output: Completion | DepthCompletionOutput | None) -> np.ndarray | None:
    """(H, W) largest fusion weight across the branches (eq. 12), or None when the method has none (classical).
    ``output``: a :class:`Completion` or its :class:`DepthCompletionOutput` (or None)."""
    if output is None:
        return None
    if not isinstance(output, Completion):
        output = Completion(np.zeros(0, np.float32), output)
    return output.confidence


@dataclass
class Prediction:
    """One completed frame as the sinks see it.

    ``depth``: (H, W) float32 metres after the hole / clamp rule (0 = hole); ``png``: its uint16 KITTI
    encoding; ``stored``: the metres the PNG holds (1/256 m steps): what the PLY and the panel use.
    ``uncertainty``: (H, W) float32 metres, 0 at the holes (None when the method gives none);
    ``uncertainty_png``: its uint16 encoding (:func:`~semattnet.inference.uncertainty.encode_uncertainty`).
    ``compress_level``: the zlib level the PNG sinks write at (the run's
    :meth:`~semattnet.inference.options.RunOptions.png_level`)."""

    frame: Frame
    completion: Completion
    depth: np.ndarray
    png: np.ndarray
    stored: np.ndarray
    stage_ms: dict[str, float] = field(default_factory=dict)  # the frame's stage times so far (the loop's)
    uncertainty: np.ndarray | None = None
    uncertainty_png: np.ndarray | None = None
    compress_level: int = PNG_COMPRESS_LEVEL
    _clouds: dict[tuple[float, int, str], PointCloud] = field(default_factory=dict, repr=False)

    @property
    def uncertainty_stored(self) -> np.ndarray | None:
        """The metres the uncertainty PNG holds (1/256 m steps; 0 = none), or None: what the limit tests."""
        return None if self.uncertainty_png is None else decode_depth(self.uncertainty_png)

    def keep(self, limit: UncertaintyLimit | None) -> np.ndarray | None:
        """The pixels a cloud keeps under ``limit`` ((H, W) bool; None: no limit, every pixel)."""
        if limit is None:
            return None
        u = self.uncertainty_stored
        if u is None:
            raise InputError(f"{self.frame.name}: --max-uncertainty: the method gives no per-pixel uncertainty")
        return limit.keep(u, self.stored)

    def cloud(self, max_depth: float, top_crop: int, limit: UncertaintyLimit | None = None) -> PointCloud:
        """The stored depth back-projected (:func:`semattnet.geometry.depth_to_points`) with the image's
        colours and the fusion confidence, the pixels ``limit`` rejects left out; needs the frame's intrinsics."""
        from semattnet.geometry import depth_to_points

        if self.frame.K is None:
            raise InputError(f"{self.frame.name}: a point cloud needs the frame's intrinsics K (--K), none given")
        key = (float(max_depth), int(top_crop), repr(limit))
        if key not in self._clouds:
            camera = None if self.frame.calib is None else self.frame.calib.camera
            name = (f"cam{camera}" if str(camera).isdigit() else str(camera)) if camera else "cam"  # KITTI "02"
            self._clouds[key] = depth_to_points(
                self.stored,
                self.frame.K,
                rgb=self.frame.rgb,
                confidence=self.completion.confidence,
                max_depth=max_depth,
                top_crop=top_crop,
                frame=name,
                mask=self.keep(limit),
            )
        return self._clouds[key]


def predict_frame(frame: Frame, completion: Completion) -> Prediction:
    """The one hole / clamp rule and the one quantisation, applied once to a frame's prediction (and to its
    uncertainty, when it has one)."""
    depth = np.asarray(clamp_for_png(np.asarray(completion.depth), frame.name), dtype=np.float32)
    png = encode_depth(depth)
    pred = Prediction(frame, completion, depth, png, decode_depth(png))
    if completion.uncertainty is not None:
        pred.uncertainty = clean_uncertainty(completion.uncertainty, depth, frame.name)
        pred.uncertainty_png = encode_uncertainty(pred.uncertainty, depth)
    return pred
