"""Datasets of an HDF5 file read as an untrusted file: only what is stored inside the file itself.

HDF5 can make a name inside a file stand for data elsewhere: an external link (another file), a soft
link (another name, which may be such a link), a virtual dataset (pieces of other files, HDF5's fill
value where a source is missing) or external raw storage (bytes of any file, ``/dev/zero`` included).
A dataset file from the internet is read here as one that may do any of these: :func:`plain_dataset`
accepts a name only when it is a hard link to a dataset whose bytes are in the file (contiguous,
chunked or compact layout), and :func:`read_bounded` reads one only after its shape and dtype passed
the caller's checks and its size the image bounds (:mod:`semattnet._utils.bounds`). Every refusal is
one :class:`~semattnet._errors.DataError` naming the file and the dataset.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import h5py  # no type hints of its own: its classes name what is passed

from semattnet._errors import DataError
from semattnet._utils.bounds import MAX_IMAGE_PIXELS

__all__ = ["MAX_DATASET_BYTES", "plain_dataset", "read_bounded"]

#: Largest dataset read, in bytes (four bytes a pixel at the image bound: 256 MiB).
MAX_DATASET_BYTES = 4 * MAX_IMAGE_PIXELS


def _refuse_link(path: Path, key: str, link: object, h5py: ModuleType) -> None:
    if isinstance(link, h5py.ExternalLink):
        raise DataError(
            f"{path}: '{key}' is an external link to {link.filename}:{link.path}; only datasets "
            "stored in the file itself are read"
        )
    if isinstance(link, h5py.SoftLink):
        raise DataError(
            f"{path}: '{key}' is a soft link to {link.path}; only datasets stored under their own name are read"
        )
    if not isinstance(link, h5py.HardLink):
        raise DataError(f"{path}: '{key}' is a {type(link).__name__}, not a dataset stored in the file")


def plain_dataset(f: h5py.File, key: str, path: Path) -> h5py.Dataset | None:
    """The ``h5py.Dataset`` ``key`` of the open file ``f`` (None when absent), when it is a hard link to a
    dataset whose bytes lie in the file; nothing is read.

    Raises:
        DataError: ``key`` is an external or soft link, a group, a virtual dataset or a dataset in external
        raw storage (one line naming ``path`` and ``key``).
    """
    import h5py

    link = f.get(key, getlink=True)
    if link is None:
        return None
    _refuse_link(path, key, link, h5py)
    obj = f.get(key)
    if not isinstance(obj, h5py.Dataset):
        raise DataError(f"{path}: '{key}' is an HDF5 {type(obj).__name__.lower()}, not a dataset")
    if obj.is_virtual:
        raise DataError(
            f"{path}: '{key}' is a virtual dataset (its data lie in other files); only datasets "
            "stored in the file itself are read"
        )
    if obj.external:
        files = ", ".join(os.fsdecode(e[0]) for e in obj.external)
        raise DataError(
            f"{path}: '{key}' keeps its data in external file(s) {files}; only datasets stored in "
            "the file itself are read"
        )
    layout = obj.id.get_create_plist().get_layout()
    if layout not in (h5py.h5d.CONTIGUOUS, h5py.h5d.CHUNKED, h5py.h5d.COMPACT):
        raise DataError(f"{path}: '{key}' has a storage layout ({layout}) other than contiguous, chunked or compact")
    return obj


def read_bounded(ds: h5py.Dataset, key: str, path: Path) -> np.ndarray:
    """The whole of dataset ``ds`` (from :func:`plain_dataset`) when it holds at most
    :data:`MAX_DATASET_BYTES` of plain numbers; checked before a byte is read.

    Raises:
        DataError: a larger dataset or one of records, strings or references (naming ``path`` and ``key``).
    """
    dtype = np.dtype(ds.dtype)
    if dtype.kind not in "biuf" or dtype.fields is not None:
        raise DataError(f"{path}: '{key}' holds {dtype}, not plain numbers")
    size = math.prod(int(n) for n in ds.shape) * dtype.itemsize
    if size > MAX_DATASET_BYTES:
        raise DataError(
            f"{path}: '{key}' declares {'x'.join(map(str, ds.shape))} {dtype} "
            f"({size / 2**20:.0f} MiB), above the limit of {MAX_DATASET_BYTES // 2**20} MiB"
        )
    return np.asarray(ds[()])
