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

Other protocols (:func:`range_metrics`, :class:`RangeMetrics`: NYU Depth v2 and VOID) score a depth range
without hole filling, as NLSPN / CompletionFormer (NYU) and KBNet (VOID) compute them: the prediction is
clamped to ``clamp``, pixels count where gt > 1e-4 m and ``min_depth <= gt <= max_depth``, the inverse of a
prediction <= 1e-4 m is 0; REL = mean |e| / gt, delta_k = fraction with max(gt/pred, pred/gt) < 1.25^k.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from semattnet._errors import DataError, InputError

__all__ = [
    "LEADERBOARD",
    "TABLE_COLUMNS",
    "KittiMetrics",
    "RangeMetrics",
    "fill_holes_kitti",
    "image_metrics",
    "range_metrics",
]

#: Names, units and scale of the official metrics (internal values are metres and 1/m).
LEADERBOARD = {
    "rmse": ("RMSE", "mm", 1000.0),
    "mae": ("MAE", "mm", 1000.0),
    "irmse": ("iRMSE", "1/km", 1000.0),
    "imae": ("iMAE", "1/km", 1000.0),
}
#: Column title and scale of each key of :meth:`KittiMetrics.compute` a table may show.
TABLE_COLUMNS = {
    "rmse_mm": ("RMSE [mm]", 1.0),
    "mae_mm": ("MAE [mm]", 1.0),
    "irmse_per_km": ("iRMSE [1/km]", 1.0),
    "imae_per_km": ("iMAE [1/km]", 1.0),
    "rmse": ("RMSE [m]", 1.0),
    "mae": ("MAE [m]", 1.0),
    "abs_rel": ("REL", 1.0),
    "delta1": ("d<1.25", 1.0),
    "delta2": ("d<1.25^2", 1.0),
    "delta3": ("d<1.25^3", 1.0),
}
_VALID_GT = 1e-4  # NLSPN's t_valid: gt at or below it counts as missing
EXTRA_METRICS = ("delta1", "delta2", "delta3", "abs_rel", "sq_rel", "log10", "silog")
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
    filled = torch.where(
        valid, rows, torch.where(~has_above & has_below, below, torch.where(has_above & ~has_below, above, 0.0))
    )
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


def range_metrics(
    pred: torch.Tensor,
    gt: torch.Tensor,
    min_depth: float = 0.0,
    max_depth: float = math.inf,
    clamp: tuple[float, float] | None = None,
) -> dict[str, torch.Tensor]:
    """Per-image metrics (same keys as :func:`image_metrics`) of (B, 1, H, W) or (B, H, W) depths in
    metres over gt > 1e-4 within ``[min_depth, max_depth]``, the prediction clamped to ``clamp`` first and
    never hole-filled (NLSPN's ``metric.py``; KBNet's ``eval_utils``). Images without such a pixel get NaN."""
    if pred.shape != gt.shape:
        raise InputError(f"prediction {tuple(pred.shape)} and ground truth {tuple(gt.shape)} differ in shape")
    pred, gt = pred.detach().double(), gt.detach().double()
    if clamp is not None:
        pred = pred.clamp(*clamp)
    b = gt.shape[0]
    pred, gt = pred.reshape(b, -1), gt.reshape(b, -1)
    mask = (gt > _VALID_GT) & (gt >= min_depth) & (gt <= max_depth)
    n = mask.sum(1).double()

    def mean(x: torch.Tensor) -> torch.Tensor:
        return torch.where(n > 0, (x * mask).sum(1) / n.clamp_min(1), torch.full_like(n, math.nan))

    err = pred - gt
    pred_inv = torch.where(pred > _VALID_GT, 1.0 / pred.clamp_min(_VALID_GT), torch.zeros_like(pred))
    inv_err = pred_inv - 1.0 / torch.where(mask, gt, torch.ones_like(gt))
    gt_s, p = torch.where(mask, gt, torch.ones_like(gt)), pred.clamp_min(1e-8)
    ratio = torch.maximum(gt_s / p, p / gt_s)
    log_diff = torch.log(pred.clamp_min(1e-3)) - torch.log(gt_s)
    return {
        "rmse": mean(err**2).sqrt(),
        "mae": mean(err.abs()),
        "irmse": mean(inv_err**2).sqrt(),
        "imae": mean(inv_err.abs()),
        "delta1": mean((ratio < 1.25).double()),
        "delta2": mean((ratio < 1.25**2).double()),
        "delta3": mean((ratio < 1.25**3).double()),
        "abs_rel": mean(err.abs() / gt_s),
        "sq_rel": mean((err / gt_s) ** 2),
        "log10": mean((torch.log10(pred.clamp_min(1e-3)) - torch.log10(gt_s)).abs()),
        "silog": (mean(log_diff**2) - mean(log_diff) ** 2).clamp_min(0).sqrt() * 100,
        "valid_pixels": n,
    }


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
        values = self.image_metrics(pred, gt)
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

    def image_metrics(self, pred: torch.Tensor, gt: torch.Tensor) -> dict[str, torch.Tensor]:
        """The per-image values of one batch (:func:`image_metrics`, the devkit's rule)."""
        return image_metrics(pred, gt, self.fill_holes, self.min_gt)

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
        out.update({k: mean[k] for k in (*LEADERBOARD, *EXTRA_METRICS)})
        return out

    def table(self) -> str:
        """The leaderboard metrics as a small text table."""
        r = self.compute()
        if getattr(self, "columns", None):
            cols = [TABLE_COLUMNS[k] for k in self.columns]  # type: ignore[attr-defined]
            head = " | ".join(name.rjust(13) for name, _ in cols)
            vals = " | ".join(f"{r[k] * scale:13.4f}" for k, (_, scale) in zip(self.columns, cols, strict=True))  # type: ignore[attr-defined]
            return f"{head}\n{vals}\n({int(r['images'])} images)"
        head = " | ".join(f"{name} [{unit}]".rjust(13) for name, unit, _ in LEADERBOARD.values())
        vals = " | ".join(
            f"{r[f'{k}_' + ('mm' if u == 'mm' else 'per_km')]:13.3f}" for k, (_, u, _) in LEADERBOARD.items()
        )
        return f"{head}\n{vals}\n({int(r['images'])} images)"


@dataclass
class RangeMetrics(KittiMetrics):
    """:class:`KittiMetrics` under a range protocol (:func:`range_metrics`): NYU Depth v2 (0.1-10 m, clamp
    0..10, NLSPN) or VOID (0.2-5 m, no clamp, KBNet). ``columns``: the keys of :meth:`compute` that
    :meth:`table` shows (:data:`TABLE_COLUMNS`).

    Example:
        >>> import torch
        >>> gt = torch.tensor([[[[1.0, 2.0], [4.0, 20.0]]]])   # 20 m: outside NYU's 10 m range
        >>> m = RangeMetrics(min_depth=0.1, max_depth=10.0, clamp=(0.0, 10.0))
        >>> _ = m.update(gt * 1.1, gt)
        >>> round(m.compute()["abs_rel"], 6), m.compute()["delta1"]
        (0.1, 1.0)
    """

    min_depth: float = 0.0
    max_depth: float = math.inf
    clamp: tuple[float, float] | None = None
    columns: tuple[str, ...] = ("rmse", "abs_rel", "delta1", "delta2", "delta3", "mae")

    def image_metrics(self, pred: torch.Tensor, gt: torch.Tensor) -> dict[str, torch.Tensor]:
        return range_metrics(pred, gt, self.min_depth, self.max_depth, self.clamp)
