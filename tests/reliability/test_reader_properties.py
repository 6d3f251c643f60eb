"""Property-based: every reader of a file format we accept, fed random or mutated bytes, either returns a valid
result or raises one SemAttNetError whose one-line message names the file; inputs stay small (a few KB), so a
size read from a header must be bounded before anything is allocated (no MemoryError, no hang)."""

from __future__ import annotations

import json
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semattnet._errors import SemAttNetError

_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow], database=None)


def _mutations(seed: bytes) -> st.SearchStrategy[bytes]:
    """``seed`` with a few bytes replaced, cut short, or extended; or plain random bytes."""
    edits = st.lists(st.tuples(st.integers(0, max(len(seed) - 1, 0)), st.integers(0, 255)), min_size=1, max_size=6)
    mutated = edits.map(lambda es: _apply(seed, es))
    cut = st.integers(0, len(seed)).map(lambda n: seed[:n])
    grown = st.binary(max_size=64).map(lambda tail: seed + tail)
    return st.one_of(mutated, cut, grown, st.binary(max_size=512))


def _apply(seed: bytes, edits: list[tuple[int, int]]) -> bytes:
    data = bytearray(seed)
    for pos, value in edits:
        data[pos] = value
    return bytes(data)


def _check(name: str, data: bytes, reader: Callable[[Path], Any], valid: Callable[[Any], bool]) -> None:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / name
        path.write_bytes(data)
        try:
            result = reader(path)
        except SemAttNetError as exc:
            msg = str(exc)
            assert "\n" not in msg.strip() and len(msg) < 2000, msg
            assert name in msg or d in msg, f"the message does not name the file: {msg}"
            return
        assert valid(result), result


def _cloud_ok(a: np.ndarray) -> bool:
    return a.ndim == 2 and a.shape[1] == 4 and a.shape[0] > 0 and bool(np.isfinite(a[:, :3]).all())


def _seed_npy() -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, np.arange(12, dtype=np.float32).reshape(3, 4))
    return buf.getvalue()


def _seed_ply() -> bytes:
    head = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        b"property float z\nend_header\n"
    )
    return head + struct.pack("<6f", 1, 2, 3, 4, 5, 6)


_PCD = b"VERSION .7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\n"
_SEED_PCD_ASCII = _PCD + b"POINTS 2\nDATA ascii\n1 2 3 4\n5 6 7 8\n"
_SEED_PCD_BINARY = _PCD + b"POINTS 2\nDATA binary\n" + struct.pack("<8f", 1, 2, 3, 4, 5, 6, 7, 8)


def _points(name: str) -> Callable[[bytes], None]:
    from semattnet.geometry import read_points

    return lambda data: _check(name, data, read_points, _cloud_ok)


@_SETTINGS
@given(_mutations(struct.pack("<8f", 1, 2, 3, 0.5, 4, 5, 6, 0.5)))
def test_bin_scans(data: bytes) -> None:
    _points("scan.bin")(data)


@_SETTINGS
@given(_mutations(_seed_npy()))
def test_npy_scans(data: bytes) -> None:
    _points("scan.npy")(data)


@_SETTINGS
@given(_mutations(_seed_ply()))
def test_ply_scans(data: bytes) -> None:
    _points("scan.ply")(data)


@_SETTINGS
@given(st.one_of(_mutations(_SEED_PCD_ASCII), _mutations(_SEED_PCD_BINARY)))
def test_pcd_scans(data: bytes) -> None:
    _points("scan.pcd")(data)


@_SETTINGS
@given(_mutations(b"1.0 2.0 3.0 0.5\n4.0,5.0,6.0,0.5\n"))
def test_text_scans(data: bytes) -> None:
    _points("scan.txt")(data)


_CAM_TO_CAM = (
    b"calib_time: 09-Jan-2012 13:57:47\nS_rect_02: 1.242000e+03 3.750000e+02\n"
    b"R_rect_02: 1 0 0 0 1 0 0 0 1\nP_rect_02: 7.2e+02 0 6.0e+02 4.4e+01 0 7.2e+02 1.7e+02 2.1e-01 0 0 1 "
    b"2.7e-03\n"
)
_VELO = b"calib_time: 15-Mar-2012 11:37:16\nR: 1 0 0 0 1 0 0 0 1\nT: 0.1 0.2 0.3\n"


@_SETTINGS
@given(_mutations(_CAM_TO_CAM))
def test_cam_to_cam_calibration(data: bytes) -> None:
    from semattnet.geometry.calibration import read_cam_to_cam

    _check(
        "calib_cam_to_cam.txt",
        data,
        read_cam_to_cam,
        lambda cams: all(0 < c.image_size[0] <= 16384 and 0 < c.image_size[1] <= 16384 for c in cams.values()),
    )


@_SETTINGS
@given(_mutations(_VELO))
def test_velo_to_cam_calibration(data: bytes) -> None:
    from semattnet.geometry.calibration import read_velo_to_cam

    _check("calib_velo_to_cam.txt", data, read_velo_to_cam, lambda T: T.shape == (4, 4) and bool(np.isfinite(T).all()))


_RIG = json.dumps(
    {
        "K": [[50, 0, 16], [0, 50, 12], [0, 0, 1]],
        "image_size": [32, 24],
        "T_cam_lidar": [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
    }
).encode()
_LEAVES = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
_JSON_VALUES = st.recursive(
    _LEAVES,
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=6), kids, max_size=4),
    max_leaves=20,
)


@_SETTINGS
@given(
    st.one_of(
        _mutations(_RIG),
        st.dictionaries(st.sampled_from(["K", "T_cam_lidar", "image_size", "camera"]), _JSON_VALUES).map(
            lambda d: json.dumps(d).encode()
        ),
    )
)
def test_rig_json(data: bytes) -> None:
    from semattnet.geometry.calibration import read_rig_json

    _check("rig.json", data, read_rig_json, lambda r: 0 < r.image_size[0] <= 16384 and 0 < r.image_size[1] <= 16384)


def _seed_safetensors() -> bytes:
    import torch
    from safetensors.torch import save

    return save({"w": torch.arange(6, dtype=torch.float32)}, metadata={"format": "pt"})


@_SETTINGS
@given(_mutations(_seed_safetensors()))
def test_safetensors_header(data: bytes) -> None:
    from semattnet.weights.checkpoint import load_checkpoint

    _check("w.safetensors", data, load_checkpoint, lambda ck: isinstance(ck.state_dict, dict))


@_SETTINGS
@given(
    st.one_of(
        _mutations(json.dumps({"arch": "semattnet", "width": 0.125}).encode()),
        st.dictionaries(st.sampled_from(["arch", "width", "iterations", "kernel_size", "x"]), _JSON_VALUES).map(
            lambda d: json.dumps(d).encode()
        ),
    )
)
def test_config_json(data: bytes) -> None:
    from semattnet.weights.hub import from_pretrained

    with tempfile.TemporaryDirectory() as d:  # config.json without weights: refused, naming the folder or file
        (Path(d) / "config.json").write_bytes(data)
        try:
            from_pretrained(d)
        except SemAttNetError as exc:
            assert "\n" not in str(exc).strip() and d in str(exc), str(exc)
        else:
            raise AssertionError("a folder without weights loaded")


@_SETTINGS
@given(st.binary(max_size=300))
def test_png_readers_name_the_file(data: bytes) -> None:
    from semattnet.data.io import read_depth, read_image, read_semantic

    for reader in (read_depth, read_image, read_semantic):
        _check("map.png", data, reader, lambda a: isinstance(a, np.ndarray) and a.size > 0)


_HOSTILE = r"""
import resource, struct, sys, tempfile, zlib
from pathlib import Path
resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))
from semattnet._errors import SemAttNetError
from semattnet.data.io import read_depth
from semattnet.geometry import read_points
from semattnet.weights.checkpoint import load_checkpoint
d = Path(tempfile.mkdtemp())
ply = b"ply\nformat {} 1.0\nelement vertex 150000000\n" + b"property float x\nproperty float y\nproperty float z\n"
ply += b"end_header\n"
(d / "a.ply").write_bytes(ply.replace(b"{}", b"ascii") + b"1 2 3\n")
(d / "b.ply").write_bytes(ply.replace(b"{}", b"binary_little_endian") + b"\0" * 24)
(d / "c.pcd").write_bytes(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 150000000\nDATA ascii\n1 2 3\n")
(d / "d.pcd").write_bytes(b"FIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 100000000\nPOINTS 1\nDATA binary\n")
npy = b"{'descr': '<f8', 'fortran_order': False, 'shape': (150000000, 3), }"
(d / "e.npy").write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", 118) + npy.ljust(117) + b"\n" + b"\0" * 24)
ihdr = struct.pack(">IIBBBBB", 16000, 16000, 16, 0, 0, 0, 0)
chunk = lambda t, b: struct.pack(">I", len(b)) + t + b + struct.pack(">I", zlib.crc32(t + b))
png = chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b"")
(d / "f.png").write_bytes(b"\x89PNG\r\n\x1a\n" + png)
head = b'{"w": {"dtype": "F32", "shape": [150000000, 8], "data_offsets": [0, 4800000000]}}'
(d / "g.safetensors").write_bytes(struct.pack("<Q", len(head)) + head + b"\0" * 16)
readers = {".ply": read_points, ".pcd": read_points, ".npy": read_points, ".png": read_depth,
           ".safetensors": load_checkpoint}
for f in sorted(d.iterdir()):
    try:
        readers[f.suffix](f)
        print(f.name, "READ")
    except SemAttNetError as e:
        assert f.name in str(e), e
        print(f.name, "refused")
"""


def test_hostile_headers_are_refused_under_a_memory_cap() -> None:
    """Headers claiming ~1-5 GB for a file of a few bytes: refused, not allocated (the process may use 3 GiB)."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-c", _HOSTILE], capture_output=True, text=True, env=env, timeout=60)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.split() == [
        w for f in "a.ply b.ply c.pcd d.pcd e.npy f.png g.safetensors".split() for w in (f, "refused")
    ], res.stdout
