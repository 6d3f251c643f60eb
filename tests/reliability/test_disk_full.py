"""A full disk: one line naming the path and the space, temporary files removed, nothing half-written
(predict, convert, archive unpacking, downloads). Needs root and ``mount -t tmpfs``; skipped otherwise."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from semattnet._utils.atomic import atomic_path, disk_full_error, is_disk_full
from semattnet._utils.outputs import staged_outputs


def _leftovers(fs: Path) -> list[Path]:
    return [p for p in fs.rglob("*") if p.is_file()]


def _cli(*args: object) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, "-m", "semattnet", *map(str, args)], capture_output=True, text=True, env=env, timeout=120
    )


def _one_line(res: subprocess.CompletedProcess[str], path: object) -> str:
    err = res.stderr.strip()
    assert res.returncode == 1 and "Traceback" not in err and len(err.splitlines()) == 1, err
    assert str(path) in err and "no space left" in err and "needed" in err, err
    return err


def test_disk_full_error_names_path_and_space(tmp_path: Path) -> None:
    exc = disk_full_error(tmp_path / "x.png", 3 * 2**20)
    assert is_disk_full(exc) and exc.filename == str(tmp_path / "x.png")
    assert "at least 3.0 MiB needed" in str(exc) and "free" in str(exc)
    assert not is_disk_full(OSError(errno.EACCES, "denied")) and not is_disk_full(ValueError())


def test_atomic_and_staged_writes_on_a_full_disk(small_fs: Path) -> None:
    with pytest.raises(OSError, match="no space left") as err, atomic_path(small_fs / "big.bin") as tmp:
        tmp.write_bytes(b"\0" * 400_000)
    assert err.value.filename == str(small_fs / "big.bin") and not _leftovers(small_fs)
    with pytest.raises(OSError, match="no space left") as err, staged_outputs(small_fs / "out") as stage:
        for i in range(10):
            (stage / f"f{i}.bin").write_bytes(b"\0" * 100_000)
    assert err.value.filename == str(small_fs / "out") and not list(small_fs.iterdir())


@pytest.mark.slow  # about a minute; the convert, unpack and download cases of a full disk run by default
def test_predict_on_a_full_disk(tmp_path: Path, small_fs: Path) -> None:
    from semattnet.data.io import write_depth, write_image

    rng = np.random.default_rng(0)
    for i in range(3):
        write_image(tmp_path / "rgb" / f"f{i}.png", rng.integers(0, 255, (128, 256, 3), dtype=np.uint8))
        d = np.zeros((128, 256), np.float32)
        d[::3, ::4] = rng.uniform(2, 60, d[::3, ::4].shape)
        write_depth(tmp_path / "sparse" / f"f{i}.png", d)
    out = small_fs / "out"
    res = _cli(
        "predict",
        "--method",
        "classical",
        "--rgb",
        tmp_path / "rgb",
        "--sparse",
        tmp_path / "sparse",
        "--npy",
        "--out",
        out,
    )
    _one_line(res, out)
    # what is left is the frames done before the disk filled, whole and journaled (a resume keeps them)
    journal = out / "frames.json"
    done = json.loads(journal.read_text())["frames"] if journal.exists() else []
    kept = {out / f for e in done if e["status"] == "done" for f in e["files"]} | ({journal} if done else set())
    assert set(_leftovers(small_fs)) == kept
    assert all(
        p.stat().st_size == e["files"][p.name]["size"]
        for e in done
        if e["status"] == "done"
        for p in (out / f for f in e["files"])
    )


def test_convert_on_a_full_disk(tmp_path: Path, small_fs: Path) -> None:
    from tests.inference._raw_sample import tiny_checkpoint

    src = tiny_checkpoint(tmp_path / "tiny.safetensors")
    assert src.stat().st_size > 300_000
    dst = small_fs / "c.safetensors"
    _one_line(_cli("convert", src, dst), dst)
    assert not _leftovers(small_fs)


def test_unpacking_and_downloading_on_a_full_disk(tmp_path: Path, small_fs: Path) -> None:
    from semattnet.cache import fetch
    from semattnet.data.archives import extract_zip

    blob = np.random.default_rng(0).bytes(400_000)
    with zipfile.ZipFile(tmp_path / "a.zip", "w") as zf:
        zf.writestr("big.bin", blob)
    with pytest.raises(OSError, match="at least") as err:
        extract_zip(tmp_path / "a.zip", small_fs / "tree")
    assert "big.bin" in str(err.value.filename) and not _leftovers(small_fs)
    (tmp_path / "remote.bin").write_bytes(blob)
    with pytest.raises(OSError, match="no space left") as err:
        fetch((tmp_path / "remote.bin").as_uri(), cache_dir=small_fs / "cache", progress=False)
    assert "remote.bin" in str(err.value.filename)
    assert not [p for p in _leftovers(small_fs) if p.suffix == ".part" or p.stat().st_size > 100_000]
