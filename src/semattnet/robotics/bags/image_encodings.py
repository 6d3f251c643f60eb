"""``sensor_msgs/Image`` camera encodings -> (H, W, 3) uint8 RGB, what the network takes: the table of those read
(:data:`BYTES_PER_PIXEL`) and the conversions (:func:`to_rgb`), as ``cv_bridge`` converts them to ``rgb8``.

- ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8`` (the alpha dropped), ``mono8`` (repeated);
- ``mono16`` scaled to 8 bits as ``cv_bridge`` does (``round(v * 255 / 65535)``), byte order from ``is_bigendian``;
- ``bayer_rggb8``, ``bayer_bggr8``, ``bayer_gbrg8``, ``bayer_grbg8``: bilinear demosaicing (each missing colour the
  mean of the nearest samples of it: the 4-neighbours that have it, else the diagonal ones);
- ``yuv422`` (UYVY: ``U0 Y0 V0 Y1``) and ``yuv422_yuy2`` (YUYV: ``Y0 U0 Y1 V0``), two pixels sharing U and V,
  BT.601 limited range as OpenCV's ``COLOR_YUV2RGB_UYVY`` / ``_YUY2`` (an even width).
"""

from __future__ import annotations

import numpy as np

from semattnet._errors import DataError

__all__ = ["BAYER_PATTERNS", "BYTES_PER_PIXEL", "to_rgb"]

#: Bytes per pixel of each encoding read.
BYTES_PER_PIXEL: dict[str, int] = {
    "rgb8": 3,
    "bgr8": 3,
    "rgba8": 4,
    "bgra8": 4,
    "mono8": 1,
    "mono16": 2,
    "bayer_rggb8": 1,
    "bayer_bggr8": 1,
    "bayer_gbrg8": 1,
    "bayer_grbg8": 1,
    "yuv422": 2,
    "yuv422_yuy2": 2,
}
#: The colour (0 R, 1 G, 2 B) of the 2x2 cell's pixels (row-major) of each Bayer encoding.
BAYER_PATTERNS: dict[str, tuple[int, int, int, int]] = {
    "bayer_rggb8": (0, 1, 1, 2),
    "bayer_bggr8": (2, 1, 1, 0),
    "bayer_gbrg8": (1, 2, 0, 1),
    "bayer_grbg8": (1, 0, 2, 1),
}
#: The RGB channels of the byte-per-channel encodings, as a slice of each pixel's bytes (a view: one strided copy
#: makes the image, where an index list gathers every byte: 3-5x slower on a 375x1242 frame).
_CHANNELS = {"rgb8": slice(0, 3), "bgr8": slice(2, None, -1), "rgba8": slice(0, 3), "bgra8": slice(2, None, -1)}


def to_rgb(rows: np.ndarray, height: int, width: int, encoding: str, bigendian: bool, topic: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB of ``rows`` ((H, W * bytes per pixel) uint8, padding dropped) in ``encoding`` (a key of
    :data:`BYTES_PER_PIXEL`).

    Raises:
        DataError: a yuv422 image of odd width; naming ``topic``.
    """
    if encoding in _CHANNELS:
        out = np.empty((height, width, 3), np.uint8)  # never a view of the message's bytes
        out[...] = rows.reshape(height, width, BYTES_PER_PIXEL[encoding])[..., _CHANNELS[encoding]]
        return out
    if encoding == "mono8":
        return np.repeat(rows.reshape(height, width, 1), 3, axis=2)
    if encoding == "mono16":
        v = np.ascontiguousarray(rows).view(">u2" if bigendian else "<u2").reshape(height, width)
        g = np.rint(v.astype(np.float32) * np.float32(255 / 65535)).astype(np.uint8)
        return np.repeat(g[..., None], 3, axis=2)
    if encoding in BAYER_PATTERNS:
        return _demosaic(rows.reshape(height, width), BAYER_PATTERNS[encoding])
    if width % 2:
        raise DataError(f"{topic}: {encoding} packs two pixels in four bytes: the width must be even, got {width}")
    return _yuv422(rows.reshape(height, width // 2, 4), encoding == "yuv422")


def _box(a: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``a`` (H, W) correlated with a 3x3 ``kernel``, zeros outside."""
    h, w = a.shape
    p = np.zeros((h + 2, w + 2), a.dtype)
    p[1:-1, 1:-1] = a
    out = np.zeros_like(a)
    for dy in range(3):
        for dx in range(3):
            if kernel[dy, dx]:
                out += kernel[dy, dx] * p[dy : dy + h, dx : dx + w]
    return out


def _demosaic(raw: np.ndarray, pattern: tuple[int, int, int, int]) -> np.ndarray:
    """Bilinear demosaicing (module doc) as normalised convolutions: a colour's samples weighted 2 at the
    4-neighbours and 1 at the diagonals, over the weights of the samples present."""
    h, w = raw.shape
    cell = np.array(pattern).reshape(2, 2)
    colour = np.tile(cell, ((h + 1) // 2, (w + 1) // 2))[:h, :w]
    kernel = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]], np.float32)
    values = raw.astype(np.float32)
    out = np.empty((h, w, 3), np.uint8)
    for c in range(3):
        mask = (colour == c).astype(np.float32)
        total, weight = _box(values * mask, kernel), _box(mask, kernel)
        mean = np.divide(total, weight, out=np.zeros_like(total), where=weight > 0)
        out[..., c] = np.where(mask > 0, raw, np.clip(np.rint(mean), 0, 255)).astype(np.uint8)
    return out


def _yuv422(quads: np.ndarray, uyvy: bool) -> np.ndarray:
    """(H, W / 2, 4) bytes of UYVY (``uyvy``) or YUYV -> (H, W, 3) RGB, BT.601 limited range."""
    q = quads.astype(np.float32)
    if uyvy:
        u, y0, v, y1 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    else:
        y0, u, y1, v = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    h, half = u.shape
    y = np.stack([y0, y1], -1).reshape(h, 2 * half) - 16
    u = np.repeat(u - 128, 2, axis=1)
    v = np.repeat(v - 128, 2, axis=1)
    rgb = np.stack([1.164 * y + 1.596 * v, 1.164 * y - 0.813 * v - 0.391 * u, 1.164 * y + 2.018 * u], -1)
    out: np.ndarray = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    return out
