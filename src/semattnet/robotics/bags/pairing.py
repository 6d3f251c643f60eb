"""Pairing camera images with LiDAR scans by header stamp.

Each image takes the scan with the nearest stamp if it lies within ``max_skew``; by default half the scan
period, which is the median spacing of the scan stamps (0.1 s, a 10 Hz LiDAR, with fewer than two scans).
A scan may serve several images; scans no image takes are counted as unused.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semattnet._errors import InputError

__all__ = ["DEFAULT_SCAN_PERIOD_NS", "StampPairing", "estimate_period_ns", "pair_stamps"]

#: The scan period assumed when the stamps cannot say (a 10 Hz LiDAR), nanoseconds.
DEFAULT_SCAN_PERIOD_NS = 100_000_000


def estimate_period_ns(stamps: np.ndarray) -> int:
    """Median spacing of distinct sorted ``stamps`` (ns), or :data:`DEFAULT_SCAN_PERIOD_NS` with fewer than two."""
    s = np.unique(np.asarray(stamps, dtype=np.int64))
    return int(np.median(np.diff(s))) if len(s) > 1 else DEFAULT_SCAN_PERIOD_NS


@dataclass(frozen=True)
class StampPairing:
    """What :func:`pair_stamps` found.

    Attributes:
        match: (n_images,) int64 scan index per image, -1 for an image with no scan within ``max_skew_ns``.
        skew_ns: (n_images,) int64 ``|image stamp - nearest scan stamp|`` (paired or not).
        max_skew_ns: the tolerance used. scan_period_ns: the estimated (or given) scan period.
        n_scans: how many scans there were.
    """

    match: np.ndarray
    skew_ns: np.ndarray
    max_skew_ns: int
    scan_period_ns: int
    n_scans: int

    @property
    def paired(self) -> int:
        """Images with a scan."""
        return int((self.match >= 0).sum())

    @property
    def dropped_images(self) -> int:
        """Images without a scan within ``max_skew_ns``."""
        return int((self.match < 0).sum())

    @property
    def unused_scans(self) -> int:
        """Scans that no image takes."""
        return self.n_scans - len(np.unique(self.match[self.match >= 0]))

    def describe(self) -> str:
        """One line: paired, dropped and unused counts and the tolerance."""
        return (
            f"{self.paired} image(s) paired with a scan within {self.max_skew_ns / 1e6:.1f} ms, "
            f"{self.dropped_images} dropped (no scan near enough), {self.unused_scans} of {self.n_scans} "
            f"scan(s) unused (scan period {self.scan_period_ns / 1e6:.1f} ms)"
        )


def pair_stamps(image_ns: np.ndarray, scan_ns: np.ndarray, max_skew_ns: int | None = None) -> StampPairing:
    """Pair each image stamp with the nearest scan stamp within ``max_skew_ns`` (default: half the scan period).

    Ties (an image exactly between two scans) go to the earlier scan.

    >>> p = pair_stamps(np.array([0, 100, 270, 500]), np.array([10, 110, 210]))
    >>> p.match.tolist(), p.max_skew_ns, p.dropped_images, p.unused_scans
    ([0, 1, -1, -1], 50, 2, 1)
    """
    img = np.asarray(image_ns, dtype=np.int64).reshape(-1)
    scans = np.asarray(scan_ns, dtype=np.int64).reshape(-1)
    period = estimate_period_ns(scans)
    tol = period // 2 if max_skew_ns is None else int(max_skew_ns)
    if tol < 0:
        raise InputError(f"max_skew: must be >= 0, got {tol / 1e9} s")
    if len(scans) == 0 or len(img) == 0:
        empty = np.full(len(img), -1, np.int64)
        return StampPairing(empty, np.full(len(img), np.iinfo(np.int64).max), tol, period, len(scans))
    order = np.argsort(scans, kind="stable")
    s = scans[order]
    right = np.clip(np.searchsorted(s, img), 0, len(s) - 1)
    left = np.clip(right - 1, 0, len(s) - 1)
    dl, dr = np.abs(img - s[left]), np.abs(s[right] - img)
    pick = np.where(dl <= dr, left, right)
    skew = np.minimum(dl, dr)
    match = np.where(skew <= tol, order[pick], -1).astype(np.int64)
    return StampPairing(match, skew, tol, period, len(scans))
