"""The library version, read late (so that modules imported by ``semattnet/__init__`` may use it)."""

from __future__ import annotations

__all__ = ["library_version"]


def library_version() -> str:
    """``semattnet.__version__``."""
    from semattnet import __version__

    return __version__
