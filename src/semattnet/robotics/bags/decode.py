"""ROS messages -> NumPy: ``sensor_msgs`` Image, CompressedImage, PointCloud2, CameraInfo, and header stamps.

The decoders take the message objects rosbags deserialises (ROS 1 and ROS 2 alike: rosbags names ROS 1's
``Header.stamp`` ``sec``/``nanosec`` too; only CameraInfo's matrices differ in case, ``K`` vs ``k``) and a
``topic`` that every error message names. Stamps are integer nanoseconds since the epoch.
"""

from __future__ import annotations

import io
import struct

import numpy as np

from semattnet._errors import DataError
from semattnet.geometry.cameras import CameraInfoData  # its home (a frame's metadata carries it)

from .image_encodings import BYTES_PER_PIXEL, to_rgb
from .messages import CameraInfoMsg, CompressedImageMsg, ImageMsg, PointCloud2Msg, PointFieldMsg, TimeMsg

__all__ = [
    "EXACT_ENCODINGS",
    "IMAGE_ENCODINGS",
    "MAX_FOCAL_PER_PIXEL",
    "MAX_POINT_COORDINATE_M",
    "POINTFIELD_DTYPES",
    "CameraInfoData",
    "decode_camera_info",
    "decode_compressed_image",
    "decode_image",
    "decode_pointcloud2",
    "header_stamp_frame",
    "msg_stamp_ns",
]

#: ``sensor_msgs/Image`` encodings read as colour: encoding -> bytes per pixel (:mod:`.image_encodings`).
IMAGE_ENCODINGS: dict[str, int] = BYTES_PER_PIXEL
#: The encodings whose colours are read exactly (a semantic image's: a demosaiced or YUV one's are not).
EXACT_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8")

#: ``sensor_msgs/PointField`` datatype constants -> NumPy type (byte order applied per message).
POINTFIELD_DTYPES: dict[int, str] = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}

#: Names of a per-point intensity field, first match wins (becomes the 4th column of the points).
_INTENSITY_NAMES = ("intensity", "reflectance", "i")

#: A LiDAR point farther than this along any axis (metres) is not a measurement: its scan is refused.
MAX_POINT_COORDINATE_M = 1000.0
#: A focal length above this many times the image's larger side (a field of view under 0.06 degrees) is refused.
MAX_FOCAL_PER_PIXEL = 1000.0


def msg_stamp_ns(stamp: TimeMsg) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time`` (``sec``, ``nanosec``)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def header_stamp_frame(rawdata: bytes | memoryview, ros1: bool) -> tuple[int, str]:
    """(stamp ns, frame id) of a serialised message that starts with ``std_msgs/Header``, without decoding the
    rest (Image, CompressedImage, PointCloud2, CameraInfo all do).

    ROS 1: ``uint32 seq, uint32 sec, uint32 nsec, uint32 len, chars``; ROS 2 CDR: a 4-byte encapsulation header
    (byte 1: 1 little-endian, 0 big-endian), ``int32 sec, uint32 nanosec, uint32 len (with NUL), chars``.
    """
    raw = bytes(rawdata[:4096])
    if ros1:
        _, sec, nsec, n = struct.unpack_from("<IIII", raw, 0)
        return sec * 1_000_000_000 + nsec, raw[16 : 16 + n].decode("utf-8", "replace").lstrip("/")
    order = "<" if raw[1] & 1 else ">"
    sec, nsec, n = struct.unpack_from(f"{order}iII", raw, 4)
    return sec * 1_000_000_000 + nsec, raw[16 : 16 + max(n - 1, 0)].decode("utf-8", "replace").lstrip("/")


def _rows(data: np.ndarray, height: int, step: int, row_bytes: int, topic: str, what: str) -> np.ndarray:
    """(height, row_bytes) uint8 view of ``data`` with rows ``step`` bytes apart (padding dropped)."""
    if step < row_bytes:
        raise DataError(f"{topic}: {what} step {step} is smaller than one row ({row_bytes} bytes)")
    need = (height - 1) * step + row_bytes if height else 0  # the last row may lack its padding
    if data.size < need:
        raise DataError(f"{topic}: {what} holds {data.size} bytes, {height} rows of {step} need {height * step}")
    if height == 0 or row_bytes == 0:
        return np.zeros((height, row_bytes), np.uint8)
    return np.lib.stride_tricks.as_strided(data, (height, row_bytes), (step, 1))


def decode_image(msg: ImageMsg, topic: str, encodings: tuple[str, ...] | None = None) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a ``sensor_msgs/Image`` in any encoding of :data:`IMAGE_ENCODINGS` (rgb8, bgr8,
    rgba8, bgra8, mono8, mono16, the four Bayer patterns, yuv422 and yuv422_yuy2: :mod:`.image_encodings`),
    honouring ``step`` (row padding); ``encodings``: those only (e.g. :data:`EXACT_ENCODINGS`).

    Raises:
        DataError: another encoding, or fewer bytes than ``height * step``; the message names the topic.
    """
    enc = str(msg.encoding).lower()
    allowed = tuple(IMAGE_ENCODINGS) if encodings is None else encodings
    if enc not in allowed:
        have = ", ".join(allowed)
        raise DataError(f"{topic}: unsupported image encoding {str(msg.encoding)!r} (semattnet reads {have})")
    h, w = int(msg.height), int(msg.width)
    data = np.ascontiguousarray(np.asarray(msg.data, dtype=np.uint8).reshape(-1))
    rows = _rows(data, h, int(msg.step), w * IMAGE_ENCODINGS[enc], topic, "image")
    bigendian = enc == "mono16" and bool(msg.is_bigendian)  # the one multi-byte encoding
    return to_rgb(rows, h, w, enc, bigendian, topic)


def decode_compressed_image(msg: CompressedImageMsg, topic: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a ``sensor_msgs/CompressedImage`` (JPEG or PNG, through Pillow).

    Raises:
        DataError: a compressed depth image, or data Pillow cannot decode; the message names the topic.
    """
    from PIL import Image, UnidentifiedImageError

    fmt = str(msg.format)
    if "compresseddepth" in fmt.lower().replace(" ", ""):
        raise DataError(f"{topic}: compressed depth images ({fmt!r}) are not colour images")
    try:
        with Image.open(io.BytesIO(np.asarray(msg.data, dtype=np.uint8).tobytes())) as img:
            return np.asarray(img.convert("RGB"), dtype=np.uint8)
    except (UnidentifiedImageError, OSError, SyntaxError) as exc:
        raise DataError(f"{topic}: cannot decode the compressed image (format {fmt!r}): {exc}") from None


def _point_dtype(msg: PointCloud2Msg, topic: str) -> tuple[np.dtype, dict[str, PointFieldMsg]]:
    """Structured dtype (itemsize ``point_step``) of a PointCloud2's x, y, z and intensity fields."""
    order = ">" if msg.is_bigendian else "<"
    listed = [str(f.name) for f in msg.fields]
    fields = {name: f for name, f in zip(listed, msg.fields, strict=True)}
    twice = [n for n in ("x", "y", "z", *_INTENSITY_NAMES) if listed.count(n) > 1]
    if twice:
        raise DataError(
            f"{topic}: PointCloud2 has {listed.count(twice[0])} fields named {twice[0]!r} (fields: "
            f"{', '.join(listed)}); which one holds the values is ambiguous"
        )
    missing = [n for n in ("x", "y", "z") if n not in fields]
    if missing:
        have = ", ".join(fields) or "none"
        raise DataError(f"{topic}: PointCloud2 has no {'/'.join(missing)} field (fields: {have})")
    names, formats, offsets = [], [], []
    for n in ("x", "y", "z"):
        f = fields[n]
        if int(f.datatype) not in (7, 8):
            raise DataError(f"{topic}: PointCloud2 field {n!r} must be FLOAT32 or FLOAT64, got datatype {f.datatype}")
        names.append(n)
        formats.append(order + POINTFIELD_DTYPES[int(f.datatype)])
        offsets.append(int(f.offset))
    intensity = next((fields[n] for n in _INTENSITY_NAMES if n in fields), None)
    if intensity is not None and int(intensity.datatype) in POINTFIELD_DTYPES:
        names.append("intensity")
        formats.append(order + POINTFIELD_DTYPES[int(intensity.datatype)])
        offsets.append(int(intensity.offset))
    step = int(msg.point_step)
    for n, fmt, off in zip(names, formats, offsets, strict=True):
        if off + np.dtype(fmt).itemsize > step:
            raise DataError(f"{topic}: PointCloud2 field {n!r} at byte {off} does not fit point_step {step}")
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    return dtype, fields


def decode_pointcloud2(msg: PointCloud2Msg, topic: str) -> np.ndarray:
    """(N, 3) or (N, 4) points of a ``sensor_msgs/PointCloud2``: x, y, z (metres, the message's frame) and
    the intensity when the cloud has one (``intensity``/``reflectance``/``i``).

    Any field layout with float32/float64 x, y, z: extra fields, padding, ``point_step`` larger than the fields,
    ``row_step`` padding, big-endian data. Points with a NaN or infinite coordinate are dropped (``is_dense``
    false: the ROS mark of a beam without a return). float32 when x, y, z all are, else float64.

    Raises:
        DataError: no x/y/z field, a field read twice (two named ``x``), an integer x/y/z, fewer bytes than the
            header says, or a finite coordinate beyond :data:`MAX_POINT_COORDINATE_M` (not a measurement);
            naming the topic.
    """
    dtype, _ = _point_dtype(msg, topic)
    h, w, step = int(msg.height), int(msg.width), int(msg.point_step)
    data = np.ascontiguousarray(np.asarray(msg.data, dtype=np.uint8).reshape(-1))
    rows = np.ascontiguousarray(_rows(data, h, int(msg.row_step), w * step, topic, "PointCloud2"))
    pts = rows.reshape(-1).view(dtype) if rows.size else np.zeros(0, dtype)
    assert dtype.fields is not None and dtype.names is not None  # a structured dtype (_point_dtype)
    xyz_types = [dtype.fields[n][0] for n in ("x", "y", "z")]
    out_type = np.float32 if all(t.itemsize == 4 for t in xyz_types) else np.float64
    cols = [pts[n].astype(out_type) for n in dtype.names]
    out = np.stack(cols, 1) if len(pts) else np.zeros((0, len(cols)), out_type)
    out = out[np.isfinite(out[:, :3]).all(1)]
    far = np.abs(out[:, :3]).max(1) > MAX_POINT_COORDINATE_M if len(out) else np.zeros(0, bool)
    if far.any():
        top = float(np.abs(out[far, :3]).max())
        raise DataError(
            f"{topic}: PointCloud2 has {int(far.sum())} of {len(pts)} point(s) beyond "
            f"{MAX_POINT_COORDINATE_M:g} m (up to {top:.3g} m); a scan is in metres in the LiDAR's frame "
            "(semattnet.robotics.bags.decode.MAX_POINT_COORDINATE_M)"
        )
    return out


def _by_case(msg: object, name: str) -> object:
    """CameraInfo's field ``name``: ``K`` in ROS 1, ``k`` in ROS 2."""
    value = getattr(msg, name.upper(), None)
    return getattr(msg, name.lower()) if value is None else value


def _matrix(msg: object, name: str, shape: tuple[int, int], topic: str) -> np.ndarray:
    arr = np.asarray(_by_case(msg, name), dtype=np.float64).reshape(-1)
    if arr.size != shape[0] * shape[1]:
        raise DataError(f"{topic}: CameraInfo {name} has {arr.size} numbers, expected {shape[0] * shape[1]}")
    return arr.reshape(shape)


def _intrinsics_set(name: str, M: np.ndarray, size: tuple[int, int], topic: str) -> bool:
    """Whether ``M`` (K or P, finite) is set; a set one needs focal lengths that are positive and not absurd."""
    if not np.any(M[:, :3]):
        return False
    for label, at in (("fx", (0, 0)), ("fy", (1, 1))):
        value, cell = float(M[at]), f"{name}[{at[0]}][{at[1]}]"
        if not value > 0:
            raise DataError(f"{topic}: CameraInfo focal length {label} ({cell}) is {value:g}, not positive")
        if value > MAX_FOCAL_PER_PIXEL * max(size):
            raise DataError(
                f"{topic}: CameraInfo focal length {label} ({cell}) is {value:.3g} pixels, more than "
                f"{MAX_FOCAL_PER_PIXEL:g} times the image's {max(size)}-pixel side"
            )
    return True


def _check_finite(matrices: dict[str, np.ndarray], topic: str) -> None:
    """Refuse the first NaN or infinite entry of CameraInfo's matrices, naming it (``fx (K[0][0])``)."""
    labels = {
        (0, 0): "focal length fx ",
        (1, 1): "focal length fy ",
        (0, 2): "principal point cx ",
        (1, 2): "principal point cy ",
    }
    for name, M in matrices.items():
        bad = np.argwhere(~np.isfinite(M))
        if len(bad):
            r, c = (int(v) for v in bad[0])
            cell = f"{name}[{c}]" if name == "D" else f"{name}[{r}][{c}]"
            label = labels.get((r, c), "") if name in ("K", "P") else ""
            value = "NaN" if np.isnan(M[r, c]) else "infinite"
            raise DataError(f"{topic}: CameraInfo {label}({cell}) is {value}")


def decode_camera_info(msg: CameraInfoMsg, topic: str) -> CameraInfoData:
    """:class:`CameraInfoData` of a ``sensor_msgs/CameraInfo`` (ROS 1 ``K``/``P`` or ROS 2 ``k``/``p``).

    Raises:
        DataError: a zero image size, a NaN or infinite number in ``K``, ``P``, ``R`` or ``D``, a set ``K`` or ``P``
            with a focal length that is not positive or above :data:`MAX_FOCAL_PER_PIXEL` times the image size,
            or neither set (uncalibrated); ``topic`` starts the message (the caller's ``BAG: TOPIC message N``).
    """
    K, P = _matrix(msg, "K", (3, 3), topic), _matrix(msg, "P", (3, 4), topic)
    R = _matrix(msg, "R", (3, 3), topic)
    D = np.asarray(_by_case(msg, "D"), dtype=np.float64).reshape(-1)
    w, h = int(msg.width), int(msg.height)
    if w <= 0 or h <= 0:
        raise DataError(f"{topic}: CameraInfo has no image size (width {w}, height {h})")
    _check_finite({"K": K, "P": P, "R": R, "D": D.reshape(1, -1)}, topic)
    if not (_intrinsics_set("K", K, (w, h), topic) | _intrinsics_set("P", P, (w, h), topic)):
        raise DataError(f"{topic}: CameraInfo is uncalibrated (K and P are all zero)")
    return CameraInfoData(
        w,
        h,
        K,
        D,
        R,
        P,
        str(msg.distortion_model),
        str(msg.header.frame_id).lstrip("/"),
        msg_stamp_ns(msg.header.stamp),
    )
