"""A PNG encoder for the arrays the sinks write: 8- or 16-bit grey and 8-bit RGB, one filter for every row.

Pillow chooses a filter for each row by trying all five (the libpng heuristic), which costs most of its time at
low zlib levels: on a 352x1216 16-bit depth map its level 0 (stored, no compression) takes about 30 ms, where the
bytes here take 2 ms. A depth map or a colour picture is smooth along its columns, so one filter for all rows
compresses about as well: "up" (each byte minus the byte above it, PNG filter 2) for levels 1-9, none for level 0.
The file is a plain PNG (signature, ``IHDR``, one ``IDAT``, ``IEND``; the PNG specification, sections 5, 9 and
11), read back by any decoder; zlib does the deflating (and releases the GIL while it works).
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from semattnet._errors import DataError

__all__ = ["encode_png"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_FILTER_NONE, _FILTER_UP = 0, 2
#: PNG colour types: 0 grey, 2 RGB.
_GREY, _RGB = 0, 2


def _chunk(kind: bytes, payload: bytes) -> bytes:
    """One PNG chunk: length, type, data and the CRC-32 of type and data."""
    crc = zlib.crc32(payload, zlib.crc32(kind))
    return b"".join((struct.pack(">I", len(payload)), kind, payload, struct.pack(">I", crc)))


def _layout(array: np.ndarray) -> tuple[int, int]:
    """``(bit depth, colour type)`` of ``array``, or a :class:`DataError` naming what it is."""
    if array.ndim == 2 and array.dtype in (np.uint8, np.uint16):
        return array.dtype.itemsize * 8, _GREY
    if array.ndim == 3 and array.shape[2] == 3 and array.dtype == np.uint8:
        return 8, _RGB
    raise DataError(f"a PNG holds (H, W) uint8 / uint16 or (H, W, 3) uint8, got {array.shape} {array.dtype}")


def encode_png(array: np.ndarray, level: int = 3) -> bytes:
    """The PNG file of ``array`` ((H, W) uint8 or uint16 grey, (H, W, 3) uint8 RGB) at zlib ``level`` 0-9.

    >>> import io; from PIL import Image
    >>> a = np.array([[0, 256, 65535]], np.uint16)
    >>> np.asarray(Image.open(io.BytesIO(encode_png(a)))).tolist()
    [[0, 256, 65535]]
    """
    if not (isinstance(level, int) and 0 <= level <= 9):
        raise DataError(f"PNG compress level must be 0 to 9, got {level!r}")
    bits, colour = _layout(array)
    h, w = array.shape[:2]
    if h == 0 or w == 0:
        raise DataError(f"a PNG needs at least one pixel, got {array.shape}")
    rows = np.ascontiguousarray(array, dtype=">u2" if bits == 16 else np.uint8).reshape(h, -1).view(np.uint8)
    scanlines = np.empty((h, rows.shape[1] + 1), np.uint8)
    scanlines[:, 0] = _FILTER_NONE if level == 0 else _FILTER_UP
    if level == 0:
        scanlines[:, 1:] = rows
    else:  # up: the first row against zeros (itself), every other against the row above, modulo 256
        scanlines[0, 1:] = rows[0]
        np.subtract(rows[1:], rows[:-1], out=scanlines[1:, 1:])
    header = struct.pack(">IIBBBBB", w, h, bits, colour, 0, 0, 0)
    return b"".join(
        (
            _SIGNATURE,
            _chunk(b"IHDR", header),
            _chunk(b"IDAT", zlib.compress(scanlines.data, level)),
            _chunk(b"IEND", b""),
        )
    )
