"""Camera encodings -> RGB (bgra8, rgba8, mono16, Bayer, yuv422) against slow per-pixel references written from
the encodings' definitions, on tiny images with row padding."""

from __future__ import annotations

import numpy as np
import pytest

from semattnet._errors import DataError
from semattnet.robotics.bags.decode import decode_image

pytest.importorskip("rosbags")

from semattnet.robotics.bags.deps import rosbags_typestore
from semattnet.robotics.bags.encode import header

TS = rosbags_typestore(False)
RNG = np.random.default_rng(7)
H, W, PAD = 5, 6, 3


def _msg(encoding: str, rows: np.ndarray, width: int = W, bigendian: bool = False) -> object:
    """An Image of ``rows`` ((H, row bytes) uint8), each row padded with PAD junk bytes."""
    padded = np.concatenate([rows, np.full((rows.shape[0], PAD), 0xEE, np.uint8)], 1)
    return TS.types["sensor_msgs/msg/Image"](
        header=header(TS, 0, "cam"),
        height=rows.shape[0],
        width=width,
        encoding=encoding,
        is_bigendian=int(bigendian),
        step=padded.shape[1],
        data=padded.reshape(-1),
    )


@pytest.mark.parametrize("encoding,alpha_at,order", [("bgra8", 3, (2, 1, 0)), ("rgba8", 3, (0, 1, 2))])
def test_four_channel_images_drop_alpha(encoding: str, alpha_at: int, order: tuple[int, ...]) -> None:
    px = RNG.integers(0, 256, (H, W, 4), np.uint8)
    got = decode_image(_msg(encoding, px.reshape(H, -1)), "/cam")  # type: ignore[arg-type]
    for y in range(H):
        for x in range(W):
            assert tuple(got[y, x]) == tuple(int(px[y, x, c]) for c in order)


@pytest.mark.parametrize("bigendian", [False, True])
def test_mono16_is_scaled_to_8_bits(bigendian: bool) -> None:
    v = RNG.integers(0, 65536, (H, W)).astype(np.uint16)
    v[0, 0], v[0, 1] = 65535, 0
    raw = v.astype(">u2" if bigendian else "<u2").view(np.uint8).reshape(H, -1)
    got = decode_image(_msg("mono16", raw, bigendian=bigendian), "/cam")  # type: ignore[arg-type]
    for y in range(H):
        for x in range(W):
            want = round(int(v[y, x]) * 255 / 65535)
            assert tuple(got[y, x]) == (want, want, want), (y, x)


def _bayer_reference(raw: np.ndarray, pattern: str) -> np.ndarray:
    """Per pixel: the colour it samples as it is; another, the mean of its 4-neighbours sampling it, else of its
    diagonal neighbours."""
    letters = pattern.removeprefix("bayer_").removesuffix("8")
    colour_of = {"r": 0, "g": 1, "b": 2}
    h, w = raw.shape
    out = np.zeros((h, w, 3), np.uint8)

    def colour(y: int, x: int) -> int:
        return colour_of[letters[2 * (y % 2) + (x % 2)]]

    for y in range(h):
        for x in range(w):
            for c in range(3):
                if colour(y, x) == c:
                    out[y, x, c] = raw[y, x]
                    continue
                for near in ([(-1, 0), (1, 0), (0, -1), (0, 1)], [(-1, -1), (-1, 1), (1, -1), (1, 1)]):
                    vals = [
                        int(raw[y + dy, x + dx])
                        for dy, dx in near
                        if 0 <= y + dy < h and 0 <= x + dx < w and colour(y + dy, x + dx) == c
                    ]
                    if vals:
                        out[y, x, c] = round(sum(vals) / len(vals))
                        break
    return out


@pytest.mark.parametrize("pattern", ["bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8"])
@pytest.mark.parametrize("size", [(H, W), (7, 9)])
def test_bayer_is_demosaiced_bilinearly(pattern: str, size: tuple[int, int]) -> None:
    raw = RNG.integers(0, 256, size, np.uint8)
    got = decode_image(_msg(pattern, raw, width=size[1]), "/cam")  # type: ignore[arg-type]
    want = _bayer_reference(raw, pattern)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("encoding", ["yuv422", "yuv422_yuy2"])
def test_yuv422_is_bt601_limited_range(encoding: str) -> None:
    raw = RNG.integers(0, 256, (H, 2 * W), np.uint8)
    got = decode_image(_msg(encoding, raw), "/cam")  # type: ignore[arg-type]
    for y in range(H):
        for x in range(W):
            quad = [int(b) for b in raw[y, 4 * (x // 2) : 4 * (x // 2) + 4]]
            u, y0, v, y1 = quad if encoding == "yuv422" else (quad[1], quad[0], quad[3], quad[2])
            luma = (y0 if x % 2 == 0 else y1) - 16
            r = 1.164 * luma + 1.596 * (v - 128)
            g = 1.164 * luma - 0.813 * (v - 128) - 0.391 * (u - 128)
            b = 1.164 * luma + 2.018 * (u - 128)
            want = tuple(min(255, max(0, round(c))) for c in (r, g, b))
            assert np.abs(np.array(got[y, x], int) - want).max() <= 1, (y, x, got[y, x], want)
    with pytest.raises(DataError, match="/cam: yuv422 packs two pixels in four bytes: the width must be even"):
        decode_image(_msg("yuv422", raw[:, :10], width=5), "/cam")  # type: ignore[arg-type]
