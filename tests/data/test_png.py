"""The PNG encoder (:mod:`semattnet.data.png`) against Pillow's decoder, which shares no code with it."""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from semattnet._errors import DataError
from semattnet.data.png import encode_png


def _decoded(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)))


@pytest.mark.parametrize("level", [0, 1, 3, 9])
@pytest.mark.parametrize(
    "shape, dtype", [((1, 1), np.uint16), ((7, 13), np.uint16), ((5, 3), np.uint8), ((4, 9, 3), np.uint8)]
)
def test_every_pixel_is_read_back_by_pillow(shape: tuple[int, ...], dtype: type, level: int) -> None:
    rng = np.random.default_rng(level)
    a = rng.integers(0, np.iinfo(dtype).max, shape, endpoint=True).astype(dtype)
    a.flat[0] = np.iinfo(dtype).max  # the extremes survive the byte order and the filter's wrap-around
    a.flat[-1] = 0
    np.testing.assert_array_equal(_decoded(encode_png(a, level)), a)


def test_a_depth_map_round_trips_and_the_levels_order_the_sizes() -> None:
    yy, xx = np.mgrid[0:352, 0:1216]
    depth = (2560 + 40 * yy + 5 * xx).astype(np.uint16)  # a smooth map, as a completion is
    depth[:100] = 0  # no depth above the horizon
    sizes = []
    for level in (0, 1, 6):
        data = encode_png(depth, level)
        np.testing.assert_array_equal(_decoded(data), depth)
        sizes.append(len(data))
    assert sizes[0] > depth.nbytes  # stored: every byte and the row filters, uncompressed
    assert sizes[0] > 10 * sizes[1] and sizes[1] >= sizes[2]


def test_the_chunks_are_as_the_specification_lays_them_out() -> None:
    data = encode_png(np.zeros((2, 3), np.uint16), 1)
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    at, kinds = 8, []
    while at < len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        kind, payload = data[at + 4 : at + 8], data[at + 8 : at + 8 + length]
        (crc,) = struct.unpack(">I", data[at + 8 + length : at + 12 + length])
        assert crc == zlib.crc32(kind + payload)
        kinds.append(kind)
        if kind == b"IHDR":
            assert struct.unpack(">IIBBBBB", payload) == (3, 2, 16, 0, 0, 0, 0)
        if kind == b"IDAT":  # filter "up" on each of the two rows of six bytes
            assert zlib.decompress(payload) == bytes([2] + [0] * 6) * 2
        at += 12 + length
    assert kinds == [b"IHDR", b"IDAT", b"IEND"]


@pytest.mark.parametrize(
    "array, level, message",
    [
        (np.zeros((2, 2), np.float32), 1, r"\(2, 2\) float32"),
        (np.zeros((2, 2, 4), np.uint8), 1, r"\(2, 2, 4\) uint8"),
        (np.zeros((0, 5), np.uint8), 1, "at least one pixel"),
        (np.zeros((2, 2), np.uint8), 10, "0 to 9, got 10"),
    ],
)
def test_what_a_png_cannot_hold_is_one_error(array: np.ndarray, level: int, message: str) -> None:
    with pytest.raises(DataError, match=message):
        encode_png(array, level)
