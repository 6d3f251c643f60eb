"""Using a completion's per-pixel uncertainty in the outputs: stored like depth, and a limit on the clouds.

* :func:`encode_uncertainty`: the uncertainty (metres) as a KITTI 16-bit PNG holds it (``metres * 256``,
  0 = no value), through the project's one quantiser (:func:`semattnet.data.io.encode_depth`). A pixel
  without depth (a hole) has no uncertainty (0); one with depth holds at least 1/256 m, so that 0 keeps
  meaning "no value", and at most 65535/256 m.
* :class:`UncertaintyLimit`: ``predict --max-uncertainty``: which pixels a point cloud keeps, by an
  absolute limit in metres (``0.5``) or one relative to the depth (``5%``: uncertainty <= 0.05 x depth).
  It is applied to the stored (quantised) uncertainty and depth, so that a resumed run, which reads the
  kept frames back from their PNGs, drops exactly the pixels the first run dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from semattnet._errors import InputError
from semattnet.data.io import MAX_DEPTH_M, MIN_DEPTH_M, encode_depth

__all__ = ["MAX_ABSOLUTE_M", "MAX_RELATIVE_PERCENT", "UncertaintyLimit", "clean_uncertainty", "encode_uncertainty"]

#: The largest absolute limit, metres (about what a 16-bit PNG holds).
MAX_ABSOLUTE_M = 255.0
#: The largest relative limit, in percent of the depth.
MAX_RELATIVE_PERCENT = 1000.0


def clean_uncertainty(uncertainty: np.ndarray, depth: np.ndarray, name: str = "prediction") -> np.ndarray:
    """(H, W) float32 metres: 0 where ``depth`` is a hole (<= 0), else the uncertainty (a NaN or infinite
    one as the largest a PNG holds, a negative one as 0). What ``uncertainty/NAME.npy`` holds."""
    u = np.asarray(uncertainty, dtype=np.float32)
    d = np.asarray(depth)
    if u.shape != d.shape:
        raise InputError(f"{name}: the uncertainty is {u.shape}, the depth {d.shape}; they must match")
    u = np.nan_to_num(u, nan=MAX_DEPTH_M, posinf=MAX_DEPTH_M, neginf=0.0).clip(min=0.0)
    return np.where(d > 0, u, np.float32(0.0)).astype(np.float32)


def encode_uncertainty(uncertainty: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(H, W) uint16, ``round(metres * 256)``: 0 where ``depth`` is a hole, else the uncertainty clamped to
    [1/256, 65535/256] m (module doc)."""
    u = clean_uncertainty(uncertainty, depth)
    return encode_depth(np.where(np.asarray(depth) > 0, np.clip(u, MIN_DEPTH_M, MAX_DEPTH_M), 0.0))


@dataclass(frozen=True)
class UncertaintyLimit:
    """Keep a pixel in a point cloud when its uncertainty is at most ``value`` metres, or (``relative``) at
    most ``value`` times its depth. :meth:`parse` reads ``--max-uncertainty``'s text."""

    value: float
    relative: bool = False

    def __post_init__(self) -> None:
        high = MAX_RELATIVE_PERCENT / 100 if self.relative else MAX_ABSOLUTE_M
        if not (math.isfinite(self.value) and 0 < self.value <= high):
            what = f"a fraction of the depth in (0, {high:g}]" if self.relative else f"metres in (0, {high:g}]"
            raise InputError(f"max uncertainty: expected {what}, got {self.value!r}")

    @classmethod
    def parse(cls, text: str) -> UncertaintyLimit:
        """``"0.5"``: 0.5 m; ``"5%"``: 5 % of the depth. One-line :class:`InputError` otherwise."""
        s = str(text).strip()
        percent = s.endswith("%")
        try:
            x = float(s[:-1] if percent else s)
        except ValueError:
            x = math.nan
        high = MAX_RELATIVE_PERCENT if percent else MAX_ABSOLUTE_M
        if not (math.isfinite(x) and 0 < x <= high):
            raise InputError(
                f"expected metres in (0, {MAX_ABSOLUTE_M:g}] (e.g. 0.5) or a percentage of the depth in "
                f"(0, {MAX_RELATIVE_PERCENT:g}%] (e.g. 5%), got {text!r}"
            )
        return cls(x / 100 if percent else x, percent)

    def __str__(self) -> str:
        return f"{self.value * 100:g}%" if self.relative else f"{self.value:g}"

    def keep(self, uncertainty: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(H, W) bool: the pixels with depth whose ``uncertainty`` (metres) passes the limit."""
        u, d = np.asarray(uncertainty, dtype=np.float64), np.asarray(depth, dtype=np.float64)
        limit = self.value * d if self.relative else self.value
        return (d > 0) & (u <= limit)
