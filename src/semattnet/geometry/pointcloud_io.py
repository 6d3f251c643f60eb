"""Reading LiDAR scans / point clouds from common formats, and writing coloured clouds as PLY.

:func:`read_points` returns (N, 4) float32: x, y, z in metres and a 4th column (reflectance/intensity,
0 when the file has none). Formats, by file suffix:

* ``.bin``: KITTI Velodyne, little-endian float32 records ``x y z reflectance`` (16 bytes each);
* ``.npy``: an (N, 3) or (N, 4) array;
* ``.txt`` / ``.csv``: N rows of 3 or 4 numbers separated by whitespace or commas (one header line allowed);
* ``.ply``: a ``vertex`` element with ``x y z`` and optionally ``intensity``/``reflectance``/``scalar_intensity``;
* ``.pcd``: PCL's format, ``DATA ascii`` or ``DATA binary``, fields ``x y z`` and optionally ``intensity``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.bounds import regular_file
from semattnet._utils.extras import require

from .projection import PointCloud

__all__ = ["read_points", "write_ply"]

_INTENSITY_NAMES = ("intensity", "reflectance", "scalar_intensity", "remission", "i")
_PCD_TYPES = {
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("I", 1): "i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
    ("U", 1): "u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
}


def _finish(xyz: np.ndarray, inten: np.ndarray | None, path: Path) -> np.ndarray:
    """Assemble (N, 4) float32 and reject empty or non-finite clouds."""
    n = xyz.shape[0]
    if n == 0:
        raise DataError(f"{path}: empty point cloud (no points)")
    out = np.zeros((n, 4), dtype=np.float32)
    out[:, :3] = xyz
    if inten is not None:
        out[:, 3] = inten
    bad = int((~np.isfinite(out[:, :3])).any(1).sum())
    if bad:
        raise DataError(f"{path}: {bad} of {n} points have NaN or infinite coordinates")
    return out


def _from_columns(a: np.ndarray, path: Path) -> np.ndarray:
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise DataError(f"{path}: expected N x 3 or N x 4 numbers (x y z [intensity]), got shape {a.shape}")
    return _finish(a[:, :3], a[:, 3] if a.shape[1] == 4 else None, path)


def _read_bin(path: Path) -> np.ndarray:
    size = path.stat().st_size
    if size == 0:
        raise DataError(f"{path}: empty scan (0 bytes)")
    if size % 16:
        raise DataError(f"{path}: {size} bytes is not a multiple of 16 (float32 x, y, z, reflectance); truncated?")
    return _from_columns(np.fromfile(path, dtype="<f4").reshape(-1, 4), path)


def _read_text(path: Path) -> np.ndarray:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text point cloud (byte {exc.start} is not UTF-8)") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if lines:
        try:
            [float(v) for v in lines[0].replace(",", " ").split()]
        except ValueError:
            lines = lines[1:]  # a header such as "x,y,z,intensity"
    try:
        rows = [[float(v) for v in ln.replace(",", " ").split()] for ln in lines]
    except ValueError as exc:
        raise DataError(f"{path}: malformed numbers: {exc}") from None
    if not rows:
        raise DataError(f"{path}: empty point cloud (no points)")
    if len({len(r) for r in rows}) != 1:
        raise DataError(f"{path}: rows have different numbers of columns")
    return _from_columns(np.array(rows, dtype=np.float64), path)


def _check_ply_counts(path: Path) -> None:
    """Every ``element NAME COUNT`` of the header at most the file's size (an element takes at least a
    byte), checked before plyfile allocates COUNT rows."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    end = head.find(b"end_header")
    for line in (head[:end] if end >= 0 else head).split(b"\n"):
        words = line.split()
        if len(words) == 3 and words[0] == b"element":
            count = words[2].decode("ascii", "replace")
            if not count.isdigit() or int(count) > size:
                raise DataError(
                    f"{path}: PLY element {words[1].decode('ascii', 'replace')!r} count {count[:24]} is "
                    f"out of range (0..{size} for this file's size)"
                )


def _read_ply(path: Path) -> np.ndarray:
    PlyData = require("plyfile", f"{path}: reading PLY").PlyData
    _check_ply_counts(path)
    try:
        ply = PlyData.read(str(path))
        v = ply["vertex"].data
    except KeyError:
        raise DataError(f"{path}: PLY has no 'vertex' element") from None
    except Exception as exc:  # plyfile raises several exception types for corrupt files
        raise DataError(f"{path}: not a readable PLY: {exc}") from None
    names = v.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise DataError(f"{path}: PLY vertices lack x, y, z (have {', '.join(names)})")
    inten = next((v[n] for n in _INTENSITY_NAMES if n in names), None)
    return _finish(np.stack([v["x"], v["y"], v["z"]], 1), inten, path)


def _pcd_header(raw: bytes, path: Path) -> tuple[dict[str, list[str]], int]:
    """PCD header fields by keyword, and the byte offset where the data starts."""
    header: dict[str, list[str]] = {}
    pos = 0
    while "DATA" not in header:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise DataError(f"{path}: PCD header has no DATA line")
        line = raw[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if line and not line.startswith("#"):
            key, *vals = line.split()
            header[key.upper()] = vals
    for key in ("FIELDS", "SIZE", "TYPE", "POINTS"):
        if key not in header:
            raise DataError(f"{path}: PCD header lacks {key}")
    return header, pos


def _check_pcd_counts(header: dict[str, list[str]], counts: list[str], size: int, path: Path) -> None:
    """POINTS in [0, file size] (a point takes at least a byte) and each COUNT >= 1, before any allocation."""
    try:
        n, per = int(header["POINTS"][0]), [int(c) for c in counts]
    except (ValueError, IndexError):
        raise DataError(f"{path}: PCD POINTS / COUNT are not integers ({header['POINTS']} / {counts})") from None
    if not 0 <= n <= size or min(per, default=1) < 1:
        raise DataError(
            f"{path}: PCD POINTS {n} / COUNT {' '.join(counts)} out of range "
            f"(POINTS in [0, {size}] for this file's size, each COUNT >= 1)"
        )
    try:
        wh = [int(header[k][0]) for k in ("WIDTH", "HEIGHT") if k in header]
    except (ValueError, IndexError):
        raise DataError(f"{path}: PCD WIDTH / HEIGHT are not integers") from None
    if len(wh) == 2 and wh[0] * wh[1] != n:
        raise DataError(f"{path}: PCD WIDTH x HEIGHT = {wh[0]} x {wh[1]} does not match POINTS {n}")


def _read_pcd(path: Path) -> np.ndarray:
    raw = path.read_bytes()
    header, start = _pcd_header(raw, path)
    fields, sizes, types = header["FIELDS"], header["SIZE"], header["TYPE"]
    counts = header.get("COUNT", ["1"] * len(fields))
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise DataError(f"{path}: PCD FIELDS, SIZE, TYPE and COUNT have different lengths")
    _check_pcd_counts(header, counts, len(raw), path)
    try:
        n = int(header["POINTS"][0])
        spec = zip(fields, sizes, types, counts, strict=True)
        dtype = np.dtype(
            [(f"{f}_{i}", _PCD_TYPES[(t.upper(), int(s))], (int(c),)) for i, (f, s, t, c) in enumerate(spec)]
        )
    except (KeyError, ValueError, IndexError):
        raise DataError(f"{path}: unsupported PCD SIZE/TYPE/COUNT {sizes} {types} {counts}") from None
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if mode == "ascii":
        text = raw[start:].decode("ascii", "replace").split()
        width = sum(int(c) for c in counts)
        if len(text) < n * width:
            raise DataError(f"{path}: PCD says {n} points but has {len(text) // max(width, 1)}")
        try:
            table = np.array(text[: n * width], dtype=np.float64).reshape(n, width)
        except ValueError as exc:
            raise DataError(f"{path}: malformed numbers: {exc}") from None
        offsets = np.cumsum([0] + [int(c) for c in counts])
        cols = {f: table[:, offsets[i]] for i, f in enumerate(fields)}
    elif mode == "binary":
        if len(raw) - start < n * dtype.itemsize:
            raise DataError(f"{path}: PCD data is truncated ({len(raw) - start} bytes for {n} points)")
        rec = np.frombuffer(raw, dtype=dtype, count=n, offset=start)
        cols = {f: rec[f"{f}_{i}"][:, 0].astype(np.float64) for i, f in enumerate(fields)}
    else:
        raise DataError(
            f"{path}: PCD 'DATA {mode}' is not supported (ascii, binary); "
            "convert it, e.g. with PCL's pcl_convert_pcd_ascii_binary"
        )
    if not {"x", "y", "z"} <= set(cols):
        raise DataError(f"{path}: PCD lacks x, y, z fields (has {', '.join(fields)})")
    inten = next((cols[k] for k in _INTENSITY_NAMES if k in cols), None)
    return _finish(np.stack([cols["x"], cols["y"], cols["z"]], 1), inten, path)


def _read_npy(path: Path) -> np.ndarray:
    """A plain numeric (N, 3|4) ``.npy`` array (no pickles, no structured or text dtypes, no ``.npz``)."""
    try:
        a = np.load(path, allow_pickle=False, mmap_mode="r")
    except Exception as exc:  # numpy's header parser raises ValueError, SyntaxError, TokenError, ...
        raise DataError(
            f"{path}: not a readable .npy array: {str(exc).splitlines()[0] if str(exc) else exc!r}"
        ) from None
    if not isinstance(a, np.ndarray):
        raise DataError(f"{path}: not a single .npy array (an .npz archive?)")
    if a.dtype.kind not in "fiu" or a.dtype.fields is not None:
        raise DataError(f"{path}: expected a numeric array of x y z [intensity], got dtype {a.dtype}")
    if a.size == 0:
        raise DataError(f"{path}: empty point cloud (no points)")
    return _from_columns(np.asarray(a, dtype=np.float64), path)


def read_points(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a scan/point cloud (format by suffix, see the module doc).

    Args:
        path: ``.bin``, ``.npy``, ``.txt``, ``.csv``, ``.ply`` or ``.pcd`` file.

    Returns:
        (N, 4) float32: x, y, z metres and reflectance/intensity (0 if the file has none).

    Raises:
        DataError: missing file, unknown suffix, wrong size or shape, no points, NaN/infinite coordinates.
    """
    path = regular_file(path, "point cloud file")
    suffix = path.suffix.lower()
    if suffix == ".bin":
        return _read_bin(path)
    if suffix == ".npy":
        return _read_npy(path)
    if suffix in (".txt", ".csv", ".xyz"):
        return _read_text(path)
    if suffix == ".ply":
        return _read_ply(path)
    if suffix == ".pcd":
        return _read_pcd(path)
    raise DataError(f"{path}: unknown point cloud format {suffix!r} (use .bin, .npy, .txt, .csv, .ply or .pcd)")


def write_ply(path: str | os.PathLike[str], cloud: PointCloud, overwrite: bool = False) -> Path:
    """Write a cloud as binary little-endian PLY, atomically.

    Vertex properties: ``x y z`` float32 (metres, in ``cloud.frame``), ``red green blue`` uchar when the cloud
    has colours, ``confidence`` float32 when it has one, then each ``cloud.values`` entry as float32.

    Returns:
        The path written.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
        DataError: empty cloud or attributes whose length differs from the number of points.
    """
    from plyfile import PlyData, PlyElement

    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
    n = len(cloud)
    if n == 0:
        raise DataError(f"{path}: refusing to write an empty point cloud")
    cols: list[tuple[str, str, np.ndarray]] = [(a, "<f4", cloud.xyz[:, i]) for i, a in enumerate("xyz")]
    if cloud.rgb is not None:
        cols += [(a, "u1", cloud.rgb[:, i]) for i, a in enumerate(("red", "green", "blue"))]
    if cloud.confidence is not None:
        cols.append(("confidence", "<f4", cloud.confidence))
    cols += [(k, "<f4", v) for k, v in cloud.values.items()]
    for name, _, col in cols:
        if len(col) != n:
            raise DataError(f"{path}: attribute {name!r} has {len(col)} values for {n} points")
    vertex = np.empty(n, dtype=[(name, t) for name, t, _ in cols])
    for name, _, col in cols:
        vertex[name] = col
    with atomic_path(path, suffix=".ply") as tmp:
        PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<").write(str(tmp))
    return path
