"""KITTI depth completion metrics, computed as the official devkit does (spec DATA.md).

Per image, over pixels with ground truth > 0: MAE and RMSE of depth (leaderboard units mm) and
iMAE / iRMSE of inverse depth (1/km); the reported value is the plain mean over images. Holes
(0) in a prediction are first filled like the devkit's ``interpolateBackground``: along each
row a gap between two valid pixels takes the smaller of their depths and the row's ends copy its
first/last valid pixel; then each column copies its first/last valid pixel up/down. A pixel that
stays empty (a row without any prediction, between filled rows) scores as depth -1 m.

Also the authors' extras and their variant counting only gt > 0.1 m (``min_gt=0.1``). Each
follows the authors' code (the metrics of Ma et al.'s self-supervised depth completion, which
PENet and SemAttNet reuse), over valid pixels p with error e = pred - gt:

* ``delta1/2/3``: fraction with max(pred/gt, gt/pred) < 1.25, 1.25^2, 1.25^3;
* ``abs_rel``: mean |e| / gt;
* ``sq_rel``: mean (e / gt)^2, i.e. the error squared over gt *squared* (dimensionless). Eigen
  et al.'s monocular-depth "Sq Rel" divides by gt once (mean e^2 / gt, in metres); compare
  numbers across papers with care;
* ``log10``: mean |log10 pred - log10 gt|;
* ``silog``: sqrt(mean d^2 - (mean d)^2) * 100 with d = ln pred - ln gt.

:class:`KittiMetrics` accumulates per-image values on any device and reduces across DDP ranks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from semattnet._errors import DataError, InputError

__all__ = ["LEADERBOARD", "KittiMetrics", "fill_holes_kitti", "image_metrics"]

#: Names, units and scale of the official metrics (internal values are metres and 1/m).
LEADERBOARD = {"rmse": ("RMSE", "mm", 1000.0), "mae": ("MAE", "mm", 1000.0),
               "irmse": ("iRMSE", "1/km", 1000.0), "imae": ("iMAE", "1/km", 1000.0)}  # fmt: skip
EXTRAS = ("delta1", "delta2", "delta3", "abs_rel", "sq_rel", "log10", "silog")
_INVALID = -1.0  # the devkit's depth for pixels without a prediction


def _fill_along(d: torch.Tensor, valid: torch.Tensor, dim: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Nearest valid value before and after each position along ``dim`` (and whether it exists)."""
    n = d.shape[dim]
    shape = [1] * d.dim()
    shape[dim] = n
    pos = torch.arange(n, device=d.device).view(shape).expand_as(d)
    before_idx = torch.where(valid, pos, torch.full_like(pos, -1)).cummax(dim=dim).values
    after_idx = torch.where(valid, pos, torch.full_like(pos, n)).flip(dim).cummin(dim=dim).values.flip(dim)
    before = torch.gather(d, dim, before_idx.clamp(0, n - 1))
    after = torch.gather(d, dim, after_idx.clamp(0, n - 1))
    return before, after, torch.stack((before_idx >= 0, after_idx < n))


def fill_holes_kitti(pred: torch.Tensor) -> torch.Tensor:
    """The devkit's hole filling on (..., H, W) depth, 0 = hole; remaining holes become -1."""
    valid = pred > 0
    before, after, (has_b, has_a) = _fill_along(pred, valid, dim=-1)
    # Gaps between two valid pixels take the nearer (smaller) depth; the ends copy their neighbour.
    ends = torch.where(has_a, after, torch.where(has_b, before, 0.0))
    rows = torch.where(valid, pred, torch.where(has_b & has_a, torch.minimum(before, after), ends))
    valid = rows > 0
    above, below, (has_above, has_below) = _fill_along(rows, valid, dim=-2)
    # Columns only extrapolate: the top copies the first valid pixel, the bottom the last.
    filled = torch.where(valid, rows, torch.where(~has_above & has_below, below,
                                                  torch.where(has_above & ~has_below, above, 0.0)))  # fmt: skip
    return torch.where(filled > 0, filled, torch.full_like(filled, _INVALID))


def image_metrics(
    pred: torch.Tensor, gt: torch.Tensor, fill_holes: bool = True, min_gt: float = 0.0
) -> dict[str, torch.Tensor]:
    """Per-image metrics of (B, 1, H, W) or (B, H, W) depths in metres; each value has shape (B,).

    Images without any ground-truth pixel get NaN (and are skipped by :class:`KittiMetrics`).
    """
    if pred.shape != gt.shape:
        raise InputError(f"prediction {tuple(pred.shape)} and ground truth {tuple(gt.shape)} differ in shape")
    pred, gt = pred.detach().double(), gt.detach().double()
    if fill_holes:
        pred = fill_holes_kitti(pred)
    mask = gt > min_gt
    b = gt.shape[0]
    pred, gt, mask = pred.reshape(b, -1), gt.reshape(b, -1), mask.reshape(b, -1)
    n = mask.sum(1).double()
    safe_n = n.clamp_min(1)

    def mean(x: torch.Tensor) -> torch.Tensor:
        return torch.where(n > 0, (x * mask).sum(1) / safe_n, torch.full_like(n, math.nan))

    gt_safe = torch.where(mask, gt, torch.ones_like(gt))
    err = pred - gt
    inv_err = 1.0 / torch.where(pred == 0, torch.full_like(pred, _INVALID), pred) - 1.0 / gt_safe
    # Extras in the authors' convention use the prediction as is (clamped to stay finite in logs).
    p = pred.clamp_min(1e-3)
    ratio = torch.maximum(p / gt_safe, gt_safe / p)
    log_diff = torch.log(p) - torch.log(gt_safe)
    out = {
        "rmse": mean(err**2).sqrt(),
        "mae": mean(err.abs()),
        "irmse": mean(inv_err**2).sqrt(),
        "imae": mean(inv_err.abs()),
        "delta1": mean((ratio < 1.25).double()),
        "delta2": mean((ratio < 1.25**2).double()),
        "delta3": mean((ratio < 1.25**3).double()),
        "abs_rel": mean(err.abs() / gt_safe),
        "sq_rel": mean((err / gt_safe) ** 2),
        "log10": mean((torch.log10(p) - torch.log10(gt_safe)).abs()),
        "silog": (mean(log_diff**2) - mean(log_diff) ** 2).clamp_min(0).sqrt() * 100,
    }
    out["valid_pixels"] = n
    return out


@dataclass
class KittiMetrics:
    """Streaming per-image KITTI metrics.

    Example:
        >>> import torch
        >>> gt = torch.full((1, 1, 4, 4), 10.0)          # (B, 1, H, W) metres, 0 = no ground truth
        >>> m = KittiMetrics()
        >>> _ = m.update(gt + 0.5, gt)                    # every pixel 0.5 m too far
        >>> round(m.compute()["rmse_mm"], 3)              # mean over images, leaderboard units
        500.0

    Args:
        fill_holes: fill prediction holes as the devkit does (official; default).
        min_gt: count pixels with gt > min_gt (0 official; 0.1 the authors' code).
        keep_per_image: keep every image's values (for a per-image CSV).
    """

    fill_holes: bool = True
    min_gt: float = 0.0
    keep_per_image: bool = True
    _sums: dict[str, float] = field(default_factory=dict)
    _count: int = 0
    per_image: list[dict[str, float | str]] = field(default_factory=list)

    def update(self, pred: torch.Tensor, gt: torch.Tensor, names: list[str] | None = None) -> dict[str, torch.Tensor]:
        values = image_metrics(pred, gt, self.fill_holes, self.min_gt)
        ok = ~torch.isnan(values["rmse"])
        for k, v in values.items():
            self._sums[k] = self._sums.get(k, 0.0) + float(v[ok].sum())
        self._count += int(ok.sum())
        if self.keep_per_image:
            for i in range(pred.shape[0]):
                row: dict[str, float | str] = {"name": names[i] if names else str(len(self.per_image))}
                row.update({k: float(v[i]) for k, v in values.items()})
                self.per_image.append(row)
        return values

    def reduce(self) -> None:
        """Sum the accumulators over DDP ranks (call on every rank before :meth:`compute`)."""
        if not (torch.distributed.is_available() and torch.distributed.is_initialized()):
            return
        keys = sorted(self._sums)
        t = torch.tensor([self._sums[k] for k in keys] + [float(self._count)], dtype=torch.float64)
        if torch.distributed.get_backend() == "nccl":
            t = t.cuda()
        torch.distributed.all_reduce(t)
        self._sums = {k: float(v) for k, v in zip(keys, t[:-1].tolist(), strict=True)}
        self._count = int(t[-1])

    def compute(self) -> dict[str, float]:
        """Means over images: ``rmse_mm``, ``mae_mm``, ``irmse_per_km``, ``imae_per_km`` (the
        leaderboard), the same in metres (``rmse`` ...), the extras, and ``images``."""
        if self._count == 0:
            raise DataError("no image with ground truth was scored")
        mean = {k: v / self._count for k, v in self._sums.items()}
        out = {"images": float(self._count)}
        for k, (_, unit, scale) in LEADERBOARD.items():
            out[f"{k}_{'mm' if unit == 'mm' else 'per_km'}"] = mean[k] * scale
        out.update({k: mean[k] for k in (*LEADERBOARD, *EXTRAS)})
        return out

    def table(self) -> str:
        """The leaderboard metrics as a small text table."""
        r = self.compute()
        head = " | ".join(f"{name} [{unit}]".rjust(13) for name, unit, _ in LEADERBOARD.values())
        vals = " | ".join(
            f"{r[f'{k}_' + ('mm' if u == 'mm' else 'per_km')]:13.3f}" for k, (_, u, _) in LEADERBOARD.items()
        )
        return f"{head}\n{vals}\n({int(r['images'])} images)"
