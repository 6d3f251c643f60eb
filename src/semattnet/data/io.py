"""PNG input/output in KITTI's encodings, with errors that name the file and the problem.

* Depth: 16-bit single-channel PNG, ``metres = value / 256``, 0 = no measurement.
* RGB and semantic maps: 8-bit colour PNG (semantic maps are colour-coded, Cityscapes palette).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, overload

import numpy as np
from PIL import Image, UnidentifiedImageError

from semattnet._errors import DataError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.bounds import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, regular_file
from semattnet.data.png import encode_png
from semattnet.geometry.transforms import Array, is_tensor

if TYPE_CHECKING:
    from torch import Tensor

__all__ = [
    "DEPTH_SCALE",
    "MAX_DEPTH_M",
    "MAX_DEPTH_VALUE",
    "MAX_IMAGE_PIXELS",
    "MAX_IMAGE_SIDE",
    "MIN_DEPTH_M",
    "PNG_COMPRESS_LEVEL",
    "STREAM_PNG_COMPRESS_LEVEL",
    "DataError",
    "clamp_for_png",
    "decode_depth",
    "encode_depth",
    "quantize_depth",
    "read_depth",
    "read_image",
    "read_intrinsics",
    "read_semantic",
    "write_depth",
    "write_image",
]

#: KITTI stores depth * 256 in uint16: one step is 1/256 m.
DEPTH_SCALE = 256.0
#: Largest stored value (uint16).
MAX_DEPTH_VALUE = 65535
#: Depths a KITTI 16-bit PNG can hold: (0, 255.996] m; 0 means "no measurement / no prediction".
MIN_DEPTH_M = 1.0 / DEPTH_SCALE
MAX_DEPTH_M = MAX_DEPTH_VALUE / DEPTH_SCALE


def _check_header(path: Path, img: Image.Image) -> None:
    """Refuse a zero or absurd size before decoding (hostile headers, decompression bombs)."""
    w, h = img.size
    if w <= 0 or h <= 0:
        raise DataError(f"{path}: the header gives an empty image ({w}x{h})")
    if w > MAX_IMAGE_SIDE or h > MAX_IMAGE_SIDE or w * h > MAX_IMAGE_PIXELS:
        raise DataError(
            f"{path}: the header gives {w}x{h} pixels, above the limit of {MAX_IMAGE_SIDE} a side "
            f"and {MAX_IMAGE_PIXELS} in all (semattnet.data.io.MAX_IMAGE_*); not decoding"
        )


def _open(path: str | os.PathLike[str]) -> Image.Image:
    path = regular_file(path, "PNG file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            img = Image.open(path)
            _check_header(path, img)
            img.load()
    except DataError:
        raise
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
        raise DataError(f"{path}: refused as a decompression bomb: {exc}") from None
    except MemoryError:
        raise DataError(f"{path}: too large to decode in memory") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise DataError(f"{path}: not a readable PNG (truncated or corrupt?): {exc}") from None
    except Exception as exc:  # PIL raises many types on hostile files (struct.error, EOFError, ...)
        raise DataError(f"{path}: not a readable PNG ({type(exc).__name__}: {exc})") from None
    return img


def read_depth(path: str | os.PathLike[str]) -> np.ndarray:
    """A KITTI depth PNG as (H, W) float32 metres (0 = no measurement).

    Raises:
        DataError: missing/corrupt file, or not a 16-bit single-channel image.
    """
    img = _open(path)
    if img.mode not in ("I;16", "I;16B", "I;16L", "I"):
        raise DataError(f"{path}: depth must be a 16-bit single-channel PNG, got mode {img.mode!r}")
    a = np.asarray(img)
    if img.mode == "I" and (a.min() < 0 or a.max() > MAX_DEPTH_VALUE):
        raise DataError(f"{path}: depth values outside the 16-bit range")
    return decode_depth(a)


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """An 8-bit colour PNG as (H, W, 3) uint8 (an alpha channel is dropped).

    Raises:
        DataError: missing/corrupt file, or not an 8-bit colour image.
    """
    img = _open(path)
    if img.mode == "RGBA":
        img = img.convert("RGB")
    if img.mode == "P":
        img = img.convert("RGB")
    if img.mode != "RGB":
        raise DataError(f"{path}: expected an 8-bit colour (RGB) PNG, got mode {img.mode!r}")
    return np.asarray(img, dtype=np.uint8)


def read_semantic(path: str | os.PathLike[str], palette: str = "cityscapes") -> np.ndarray:
    """A colour-coded semantic map as (H, W, 3) uint8, checked against ``palette`` (Cityscapes by default;
    see :data:`semattnet.palette.PALETTES`).

    Raises:
        DataError: missing/corrupt file or not 8-bit colour.
        UnknownColorError: pixels outside the palette (a resampled or JPEG-resaved map).
    """
    from semattnet.palette import colors_to_ids

    colors = read_image(path)
    colors_to_ids(colors, allow_unknown=True, source=str(path), palette=palette)
    return colors


def encode_depth(depth: np.ndarray) -> np.ndarray:
    """Metres -> KITTI uint16 (round(d * 256)); 0 stays 0 (no measurement), values clamp at 65535.
    The one quantiser of the project: :func:`quantize_depth` and :func:`write_depth` use it."""
    d = np.asarray(depth, dtype=np.float64)
    if not np.all(np.isfinite(d)):
        raise DataError("depth to encode contains NaN or infinite values")
    return np.clip(np.round(d * DEPTH_SCALE), 0, MAX_DEPTH_VALUE).astype(np.uint16)


def decode_depth(values: np.ndarray) -> np.ndarray:
    """KITTI uint16 -> (H, W) float32 metres (``value / 256``, 0 = none)."""
    return (np.asarray(values).astype(np.float32) / DEPTH_SCALE).astype(np.float32)


@overload
def quantize_depth(depth: Tensor) -> Tensor: ...
@overload
def quantize_depth(depth: np.ndarray) -> np.ndarray: ...
def quantize_depth(depth: Array) -> Array:
    """Metres as a KITTI 16-bit PNG stores them (1/256 m steps, clamped to the uint16 range), as float32
    metres; a NumPy array (via :func:`encode_depth`) or a torch tensor (same device). Finite input only:
    apply :func:`clamp_for_png` first for predictions."""
    if is_tensor(depth):
        import torch

        if not bool(torch.isfinite(depth).all()):
            raise DataError("depth to encode contains NaN or infinite values")
        return torch.clamp(torch.round(depth * DEPTH_SCALE), 0, MAX_DEPTH_VALUE) / DEPTH_SCALE
    return decode_depth(encode_depth(depth))


@overload
def clamp_for_png(depth: Tensor, name: str = "prediction") -> Tensor: ...
@overload
def clamp_for_png(depth: np.ndarray, name: str = "prediction") -> np.ndarray: ...
def clamp_for_png(depth: Array, name: str = "prediction") -> Array:
    """What a KITTI 16-bit PNG of a prediction holds, before rounding to 1/256 m: the one rule every
    PNG the project writes follows (``predict``, ``evaluate``'s predictions and PNG-exact scoring, ``submit``).

    * A hole (0, negative or non-finite: no prediction) stays 0. The devkit reads 0 as "no prediction"
      and fills it from its neighbours; any other value is scored as a real depth, and 1/256 m
      (3.9 mm) would add hundreds of 1/km to iRMSE. Holes are counted in a warning naming the frame.
    * A real depth below 1/256 m clamps to 1/256 m, one above 65535/256 m to 65535/256 m (warned).

    ``depth``: a NumPy array or a torch tensor (returned as the same type, same device).
    """
    xp: ModuleType  # torch or numpy: the same calls on either
    d: Array
    if is_tensor(depth):
        import torch as xp

        d = depth
    else:
        xp, d = np, np.asarray(depth)
        d = d if np.issubdtype(d.dtype, np.floating) else d.astype(np.float64)
    hole = ~xp.isfinite(d) | (xp.nan_to_num(d, nan=0.0) <= 0)
    holes = int(hole.sum())
    low, high = int((~hole & (d < MIN_DEPTH_M)).sum()), int((~hole & (d > MAX_DEPTH_M)).sum())
    if holes:
        warnings.warn(
            f"{name}: {holes} hole(s) (no prediction: 0, negative or not finite) written as 0, "
            "which the KITTI devkit fills",
            stacklevel=2,
        )
    if low or high:
        warnings.warn(
            f"{name}: clamped {low} pixel(s) below {MIN_DEPTH_M:.4f} m and {high} above "
            f"{MAX_DEPTH_M:.2f} m to KITTI's 16-bit range",
            stacklevel=2,
        )
    clamped = xp.clip(xp.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0), MIN_DEPTH_M, MAX_DEPTH_M)
    out: Array = xp.where(hole, xp.zeros_like(clamped), clamped)
    return out


#: The zlib level of the PNGs we write (:mod:`semattnet.data.png`). 3 (zlib's fast strategy) against PIL's default 6,
#: measured on a 352x1216 dense depth map: 37 ms instead of 194 ms at the same size (450 kB), and an 18 ms colour
#: map at +32 % size. Writing at 6 cost 7-20 % of a frame in ``predict --stream`` (issue 36); the pixels are the same.
PNG_COMPRESS_LEVEL = 3
#: The zlib level of the PNGs a paced or read-ahead run writes (``predict --realtime`` / ``--stream``:
#: :meth:`semattnet.inference.options.RunOptions.png_level`), where the writing shares the CPU with the network.
#: Measured on the real 375x1242 frame's classical completion (AMD EPYC, AVX2, busy): the depth PNG 17 ms
#: (223 kB) against 36 ms at level 3 (208 kB) and PIL's 42 ms at level 1; its colour picture 7 ms; the pixels
#: are the same.
STREAM_PNG_COMPRESS_LEVEL = 1


def _atomic_save(array: np.ndarray, path: Path, overwrite: bool, compress_level: int = PNG_COMPRESS_LEVEL) -> Path:
    """``array`` as a PNG at ``path`` (:func:`semattnet.data.png.encode_png`), atomically."""
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite")
    data = encode_png(array, compress_level)
    with atomic_path(path, suffix=".png") as tmp:
        Path(tmp).write_bytes(data)
    return path


def write_depth(
    path: str | os.PathLike[str], depth: np.ndarray, overwrite: bool = False, compress_level: int = PNG_COMPRESS_LEVEL
) -> Path:
    """Write (H, W) metres as a KITTI 16-bit PNG, atomically; refuses to overwrite by default.
    A uint16 array is taken as already encoded (:func:`encode_depth`) and written as is.

    Raises:
        DataError: NaN / infinite, negative or deeper than :data:`MAX_DEPTH_M` metres (what the PNG cannot
            hold; apply :func:`clamp_for_png` to predictions first), naming ``path``.
    """
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise DataError(f"{path}: depth must be (H, W), got shape {depth.shape}")
    if depth.dtype != np.uint16:
        d = np.asarray(depth, dtype=np.float64)
        finite = bool(np.all(np.isfinite(d)))
        if d.size and not (finite and d.min() >= 0 and np.round(d.max() * DEPTH_SCALE) <= MAX_DEPTH_VALUE):
            bad = d[~np.isfinite(d)] if not finite else d[(d < 0) | (d > MAX_DEPTH_M)]
            raise DataError(
                f"{path}: depth to write has {bad.size} value(s) like {bad.flat[0]:g} m; a KITTI "
                f"16-bit PNG holds 0 (none) to {MAX_DEPTH_M:.2f} m (clamp_for_png clamps)"
            )
    values = depth if depth.dtype == np.uint16 else encode_depth(depth)
    return _atomic_save(values, Path(path), overwrite, compress_level)


def write_image(
    path: str | os.PathLike[str], image: np.ndarray, overwrite: bool = False, compress_level: int = PNG_COMPRESS_LEVEL
) -> Path:
    """Write (H, W, 3) uint8 as an RGB PNG, atomically; refuses to overwrite by default."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise DataError(f"{path}: image must be (H, W, 3) uint8, got {image.shape} {image.dtype}")
    return _atomic_save(image, Path(path), overwrite, compress_level)


def read_intrinsics(path: str | os.PathLike[str], camera: str | None = None) -> np.ndarray:
    """A 3x3 camera matrix from a KITTI file.

    ``val_selection_cropped``/``test`` intrinsics files hold 9 numbers; a raw-data
    ``calib_cam_to_cam.txt`` holds ``P_rect_0X`` rows (pass ``camera="02"``): ``K = P_rect_0X[:, :3]``,
    read by the one KITTI calibration reader, :func:`semattnet.geometry.calibration.read_projection`
    (which keeps the last column, the stereo baseline, for those who need it).
    """
    path = Path(path)
    if camera is not None:
        from semattnet.geometry.calibration import read_projection

        K: np.ndarray = read_projection(path, camera)[:, :3].copy()
        return K
    if not path.is_file():
        raise DataError(f"{path}: file not found")
    try:
        values = [float(v) for v in path.read_text().split()]
    except ValueError as exc:
        raise DataError(f"{path}: malformed numbers: {exc}") from None
    if len(values) != 9:
        raise DataError(f"{path}: expected 9 numbers (a 3x3 matrix), found {len(values)}")
    return np.array(values, dtype=np.float64).reshape(3, 3)
