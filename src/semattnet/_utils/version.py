"""The library version: one home, below every module that reports it (``semattnet.__version__`` is this)."""

from __future__ import annotations

__all__ = ["__version__", "library_version"]

__version__ = "0.1.0"


def library_version() -> str:
    """``semattnet.__version__``."""
    return __version__
