"""NumPy -> ROS messages (rosbags message objects of a type store): the inverse of :mod:`.decode`.

Every builder takes the rosbags type store ``ts`` (ROS 1 Noetic or ROS 2 Humble, from
:func:`semattnet.robotics.bags.deps.rosbags_typestore`), a stamp in integer nanoseconds and a frame id.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np

from semattnet._errors import InputError

from .decode import CameraInfoData
from .deps import Typestore

__all__ = [
    "camera_info_message",
    "compressed_image_message",
    "depth_image_message",
    "header",
    "image_message",
    "pack_rgb",
    "pointcloud2_message",
    "tf_message",
]

#: NumPy kind + size -> ``sensor_msgs/PointField`` datatype.
_FIELD_TYPES = {("i", 1): 1, ("u", 1): 2, ("i", 2): 3, ("u", 2): 4, ("i", 4): 5, ("u", 4): 6, ("f", 4): 7, ("f", 8): 8}


def _time(ts: Typestore, ns: int) -> object:
    return ts.types["builtin_interfaces/msg/Time"](sec=int(ns) // 1_000_000_000, nanosec=int(ns) % 1_000_000_000)


def _has_field(cls: type, name: str) -> bool:
    """Whether the message class ``cls`` has the field ``name`` (where ROS 1 and ROS 2 differ)."""
    return name in vars(cls)["__dataclass_fields__"]


def header(ts: Typestore, stamp_ns: int, frame_id: str, seq: int = 0) -> object:
    """A ``std_msgs/Header`` (ROS 1 has a ``seq``, ROS 2 not)."""
    cls = ts.types["std_msgs/msg/Header"]
    if _has_field(cls, "seq"):
        return cls(seq=seq, stamp=_time(ts, stamp_ns), frame_id=frame_id)
    return cls(stamp=_time(ts, stamp_ns), frame_id=frame_id)


def _image(ts: Typestore, pixels: np.ndarray, encoding: str, stamp_ns: int, frame_id: str) -> object:
    """``sensor_msgs/Image`` of C-contiguous little-endian ``pixels`` (H, W[, C]), rows unpadded."""
    h, w = pixels.shape[:2]
    step = int(np.prod(pixels.shape[1:])) * pixels.itemsize
    return ts.types["sensor_msgs/msg/Image"](
        header=header(ts, stamp_ns, frame_id),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=step,
        data=pixels.reshape(-1).view(np.uint8),
    )


def image_message(ts: Typestore, rgb: np.ndarray, stamp_ns: int, frame_id: str) -> object:
    """``sensor_msgs/Image`` rgb8 of an (H, W, 3) uint8 image (``step = 3 W``)."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InputError(f"image: expected (H, W, 3) uint8, got shape {rgb.shape}")
    return _image(ts, rgb, "rgb8", stamp_ns, frame_id)


def depth_image_message(ts: Typestore, depth: np.ndarray, stamp_ns: int, frame_id: str) -> object:
    """``sensor_msgs/Image`` 32FC1 in metres (REP 118): pixels without depth (<= 0 or not finite) are NaN."""
    d = np.asarray(depth, dtype=np.float32)
    if d.ndim != 2:
        raise InputError(f"depth: expected (H, W) metres, got shape {d.shape}")
    bad = (d <= 0) | (d == np.inf)  # NaN compares False: already a hole
    d = np.where(bad, np.float32(np.nan), d) if bad.any() else d
    d = np.ascontiguousarray(d.astype("<f4", copy=False))
    return _image(ts, d, "32FC1", stamp_ns, frame_id)


def compressed_image_message(ts: Typestore, rgb: np.ndarray, stamp_ns: int, frame_id: str, fmt: str = "png") -> object:
    """``sensor_msgs/CompressedImage`` of an (H, W, 3) uint8 image, ``fmt`` "png" (lossless) or "jpeg"."""
    from PIL import Image

    if fmt not in ("png", "jpeg"):
        raise InputError(f"compressed image format: expected 'png' or 'jpeg', got {fmt!r}")
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8)).save(buf, format=fmt.upper(), quality=95)
    return ts.types["sensor_msgs/msg/CompressedImage"](
        header=header(ts, stamp_ns, frame_id), format=fmt, data=np.frombuffer(buf.getvalue(), np.uint8)
    )


def pack_rgb(rgb: np.ndarray) -> np.ndarray:
    """(N,) float32 of (N, 3) uint8 colours packed as RViz reads a PointCloud2 ``rgb`` field:
    the bits of ``uint32 (r << 16) | (g << 8) | b`` reinterpreted as float32."""
    c = np.asarray(rgb, dtype=np.uint32)
    return ((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).astype("<u4").view("<f4")


def pointcloud2_message(
    ts: Typestore, fields: dict[str, np.ndarray], stamp_ns: int, frame_id: str, is_dense: bool | None = None
) -> object:
    """An unorganised (height 1) little-endian ``sensor_msgs/PointCloud2`` with one (N,) column per field,
    packed without padding in the given order (e.g. ``{"x": ..., "y": ..., "z": ..., "intensity": ...}``).

    ``is_dense`` None: True when no x/y/z is NaN or infinite.
    """
    cols = {k: np.asarray(v).reshape(-1) for k, v in fields.items()}
    n = {len(v) for v in cols.values()}
    if len(n) != 1:
        raise InputError(f"PointCloud2 fields must have one length, got { ({k: len(v) for k, v in cols.items()}) }")
    dtype = np.dtype([(k, v.dtype.newbyteorder("<")) for k, v in cols.items()])
    assert dtype.fields is not None  # a structured dtype
    arr = np.empty(n.pop(), dtype)
    for k, v in cols.items():
        arr[k] = v
    Field = ts.types["sensor_msgs/msg/PointField"]
    pf = [
        Field(name=k, offset=dtype.fields[k][1], datatype=_FIELD_TYPES[(v.dtype.kind, v.dtype.itemsize)], count=1)
        for k, v in cols.items()
    ]
    if is_dense is None:
        xyz = [cols[k] for k in ("x", "y", "z") if k in cols]
        is_dense = bool(all(np.isfinite(c).all() for c in xyz))
    return ts.types["sensor_msgs/msg/PointCloud2"](
        header=header(ts, stamp_ns, frame_id),
        height=1,
        width=len(arr),
        fields=pf,
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * len(arr),
        data=arr.view(np.uint8).reshape(-1),  # the packed array's bytes, not a copy of them
        is_dense=is_dense,
    )


def camera_info_message(
    ts: Typestore, info: CameraInfoData, stamp_ns: int | None = None, frame_id: str | None = None
) -> object:
    """``sensor_msgs/CameraInfo`` of :class:`CameraInfoData` (stamp and frame id from ``info`` unless given)."""
    cls = ts.types["sensor_msgs/msg/CameraInfo"]
    ros1 = _has_field(cls, "K")
    mats = {"D": info.D, "K": info.K, "R": info.R, "P": info.P}
    kw = {(k if ros1 else k.lower()): np.array(v, dtype=np.float64).reshape(-1) for k, v in mats.items()}  # copies
    roi = ts.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    hdr = header(ts, info.stamp_ns if stamp_ns is None else stamp_ns, info.frame_id if frame_id is None else frame_id)
    return cls(
        header=hdr,
        height=int(info.height),
        width=int(info.width),
        distortion_model=info.distortion_model,
        binning_x=0,
        binning_y=0,
        roi=roi,
        **kw,
    )


def tf_message(ts: Typestore, transforms: Sequence[tuple[str, str, np.ndarray]], stamp_ns: int) -> object:
    """``tf2_msgs/TFMessage`` of ``(parent, child, T_parent_child (4, 4))`` edges (``p_parent = T p_child``)."""
    from .tf import matrix_to_quaternion

    g = ts.types
    out = []
    for parent, child, T in transforms:
        T = np.asarray(T, dtype=np.float64)
        x, y, z, w = matrix_to_quaternion(T[:3, :3])
        vec = g["geometry_msgs/msg/Vector3"](x=T[0, 3], y=T[1, 3], z=T[2, 3])
        tr = g["geometry_msgs/msg/Transform"](
            translation=vec, rotation=g["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
        )
        stamped = g["geometry_msgs/msg/TransformStamped"]
        out.append(stamped(header=header(ts, stamp_ns, parent), child_frame_id=child, transform=tr))
    return g["tf2_msgs/msg/TFMessage"](transforms=out)
