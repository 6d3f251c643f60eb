"""Released weights in the verified download cache (:mod:`semattnet.cache`).

What is specific to weights: a :class:`~semattnet.weights.PretrainedWeights` record becomes a cache
target ``<cache>/<weights name>/<file name>`` with the record's mirrors, sha256 and size.
"""

from __future__ import annotations

from pathlib import Path

from semattnet.cache import Target, check_file_name
from semattnet.weights.pretrained import PretrainedWeights

__all__ = ["weights_target"]


def weights_target(entry: PretrainedWeights, sha256: str | None, root: Path, file_name: str | None = None) -> Target:
    """The cache target of a registry record (``sha256`` overrides the record's)."""
    name = check_file_name(file_name or entry.file_name)
    return Target(entry.urls, root / entry.name / name, sha256 or entry.sha256, entry.size_bytes, entry.name)
