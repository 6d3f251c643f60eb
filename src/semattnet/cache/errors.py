"""The errors of the download cache: each a :class:`~semattnet.SemAttNetError` and an ``OSError``."""

from __future__ import annotations

from semattnet._errors import InputError, SemAttNetError

__all__ = ["ChecksumError", "DownloadError", "NotAFileError", "OfflineError"]


class DownloadError(OSError, SemAttNetError):
    """A file could not be fetched (every URL failed).

    Also an ``OSError`` (a failed transfer is an I/O failure), so ``except OSError`` keeps catching it."""


class ChecksumError(DownloadError):
    """A file's sha256 or size differs from the published, given or pinned value."""


class OfflineError(DownloadError):
    """Offline mode is on and the file is not in the cache."""


class NotAFileError(InputError):
    """A ``file://`` URL naming a FIFO, a device or a folder (a copy would block or never end): not retried."""
