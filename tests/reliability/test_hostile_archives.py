"""A hostile dataset archive unpacks nothing: a symlink member, a member name given twice or a zip bomb is one
``UnsafeArchiveError`` line naming the archive, and no file appears under the destination."""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.reliability._helpers import one_line as _one_line


def _void_zip(path: Path, write: Callable[[zipfile.ZipFile], None]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        write(zf)
    return path


def _link(zf: zipfile.ZipFile) -> None:
    info = zipfile.ZipInfo("void/lnk")
    info.external_attr, info.create_system = 0o120777 << 16, 3
    zf.writestr(info, "/etc/passwd")


def _twice(zf: zipfile.ZipFile) -> None:
    zf.writestr("void/a.txt", "1")
    with pytest.warns(UserWarning, match="Duplicate"):
        zf.writestr("void/a.txt", "22")


def _bomb(zf: zipfile.ZipFile) -> None:
    with zf.open("void/bomb.bin", "w") as f:
        for _ in range(72):  # 72 MiB of zeros in ~70 KiB
            f.write(bytes(1 << 20))


@pytest.mark.parametrize("write", [_link, _twice, _bomb], ids=["symlink", "duplicate", "bomb"])
def test_hostile_dataset_archives_unpack_nothing(tmp_path: Path, write: Callable[[zipfile.ZipFile], None]) -> None:
    from semattnet.data.archives import UnsafeArchiveError, extract_zip

    archive = _void_zip(tmp_path / "a.zip", write)
    msg = _one_line(lambda: extract_zip(archive, tmp_path / "dest"), UnsafeArchiveError)
    assert "a.zip" in msg and "nothing unpacked" in msg
    assert not [p for p in (tmp_path / "dest").rglob("*") if p.is_file()]
