"""What ``semattnet predict --max-uncertainty`` buys: the share of cloud points kept and their error.

Completes the held-out (val_select) scenes of a synthetic tree with trained weights, turns every frame into
what ``predict`` writes (:func:`semattnet.inference.sinks.predict_frame`: the depth and the uncertainty as
their 16-bit PNGs store them) and, for each limit, keeps the pixels that
:class:`semattnet.inference.uncertainty.UncertaintyLimit` keeps (the PLY's points, up to ``--max-depth``).
For the kept points with ground truth it reports the RMSE of the 3D point against the ground-truth point on
the same ray (``|d - gt| * |K^-1 (u, v, 1)|``, metres) and the share of them more than 1 m off (flying
pixels), all scenes pooled. ``--picture`` draws one scene's cloud from above, before and after a limit.

Typical use (the demo's held-out scenes, the shipped reference weights)::

    semattnet synth --out /tmp/unc-data --frames 1 --eval-frames 16 --size 96x320 --style realistic --seed 0
    python benchmarks/bench_uncertainty_filter.py /tmp/unc-data \\
        --weights semattnet-demo-ref-seed0 semattnet-demo-ref-seed1 \\
        --picture docs/guides/uncertainty-cloud.png
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from semattnet._utils.cpu import cpu_summary
from semattnet.apps.experiment import HeldOut, load_held_out
from semattnet.data.frames import Frame
from semattnet.inference.completer import Completion
from semattnet.inference.sinks import Prediction, predict_frame
from semattnet.inference.uncertainty import UncertaintyLimit

LIMITS = ("none", "20", "10", "5", "3", "2", "100%", "50%", "30%", "20%")
MAX_DEPTH = 80.0
FLYING_M = 1.0


def _predictions(weights: str, held: HeldOut) -> list[tuple[Prediction, np.ndarray]]:
    """(what predict writes, ground truth) per held-out scene."""
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.inference import DepthCompleter
    from semattnet.inference.backends import EngineSpec
    from semattnet.weights.hub import from_pretrained

    completer: Any = (
        ClassicalCompleter()
        if weights == "classical"
        else DepthCompleter(from_pretrained(weights, progress=False), EngineSpec(device="cpu"))
    )
    out = []
    for s in held.samples:
        rgb = s["rgb"].permute(1, 2, 0).numpy().astype(np.uint8)
        sem = s["semantic"].permute(1, 2, 0).numpy().astype(np.uint8)
        sparse = s["sparse"][0].numpy()
        res: Completion = completer(rgb, sparse, sem)
        frame = Frame(str(s["name"]), rgb, sparse, semantic=sem, K=s["K"].numpy().astype(np.float64))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # holes, if any, are counted by predict_frame's warning
            out.append((predict_frame(frame, res), s["gt"][0].numpy()))
    return out


def _point_errors(pred: Prediction, gt: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """3D distance of each kept point with ground truth from the ground-truth point on its ray, metres."""
    K = np.asarray(pred.frame.K)
    v, u = np.nonzero(keep & (gt > 0))
    ray = np.linalg.norm(np.linalg.solve(K, np.stack([u, v, np.ones_like(u)]).astype(np.float64)), axis=0)
    return np.abs(pred.stored[v, u].astype(np.float64) - gt[v, u]) * ray


def table(weights: str, preds: list[tuple[Prediction, np.ndarray]]) -> list[str]:
    """One row per limit: points kept, RMSE of the kept points with ground truth, share > 1 m off."""
    rows = []
    base = sum(int(((p.stored > 0) & (p.stored <= MAX_DEPTH)).sum()) for p, _ in preds)
    for text in LIMITS:
        limit = None if text == "none" else UncertaintyLimit.parse(text)
        kept, errs = 0, []
        for p, gt in preds:
            keep = (p.stored > 0) & (p.stored <= MAX_DEPTH)
            if limit is not None:
                k = p.keep(limit)
                assert k is not None
                keep &= k
            kept += int(keep.sum())
            errs.append(_point_errors(p, gt, keep))
        e = np.concatenate(errs)
        rmse = float(np.sqrt(np.mean(e**2))) if e.size else float("nan")
        flying = 100 * float(np.mean(e > FLYING_M)) if e.size else float("nan")
        shown = "(all points)" if limit is None else f"`{text}`"
        rows.append(f"| {weights} | {shown} | {100 * kept / base:.1f} % | {rmse:.3f} | {flying:.2f} % |")
    return rows


def picture(path: Path, weights: str, pred: Prediction, gt: np.ndarray, text: str, view_m: float = 50.0) -> None:
    """The scene's cloud from above and from the side (up to ``view_m`` ahead), all points and those ``text``
    keeps, coloured by their distance from the ground truth (grey: no ground truth)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    limit = UncertaintyLimit.parse(text)
    fig, axes = plt.subplots(2, 2, figsize=(8.0, 5.6), sharex=True, dpi=90, height_ratios=[2, 1])
    for col, lim, title in ((0, None, "all points"), (1, limit, f"--max-uncertainty {text}")):
        cloud = pred.cloud(MAX_DEPTH, 0, lim)
        u, v = cloud.uv[:, 0].astype(int), cloud.uv[:, 1].astype(int)
        err = np.abs(pred.stored[v, u] - gt[v, u])
        has = gt[v, u] > 0
        for row, (axis, name) in enumerate(((0, "left (m)"), (1, "up (m)"))):
            ax = axes[row, col]
            side = -cloud.xyz[:, axis]  # camera x right, y down
            ax.scatter(cloud.xyz[~has, 2], side[~has], s=0.3, c="0.7", linewidths=0)
            sc = ax.scatter(
                cloud.xyz[has, 2], side[has], s=0.8, c=err[has], cmap="inferno_r", vmin=0, vmax=3, linewidths=0
            )
            if col == 0:
                ax.set_ylabel(name, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.set_xlim(0, view_m)
            ax.set_ylim(*((-view_m / 2, view_m / 2) if axis == 0 else (-3, 8)))
        axes[0, col].set_title(f"{title}: {len(cloud.xyz)} points", fontsize=9)
        axes[1, col].set_xlabel("z (m, forward)", fontsize=8)
    fig.colorbar(sc, ax=axes, shrink=0.7, label="error vs ground truth (m; grey: none)")
    fig.suptitle(f"{weights}, held-out scene ...{pred.frame.name[-28:]}: from above (top), from the side", fontsize=9)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", type=Path, help="a synthetic tree (semattnet synth / demo) with scenes.json")
    p.add_argument(
        "--weights",
        nargs="+",
        default=["semattnet-demo-ref-seed0", "semattnet-demo-ref-seed1"],
        help="weights names or files ('classical': the baseline)",
    )
    p.add_argument("--picture", type=Path, default=None, help="write the before/after cloud of one scene here")
    p.add_argument("--scene", type=int, default=3, help="with --picture: the held-out scene's index")
    p.add_argument("--picture-limit", default="5", help="with --picture: the limit drawn")
    args = p.parse_args()
    held = load_held_out(args.data)
    print(
        f"{len(held.names)} held-out scenes of {args.data}, {tuple(held.samples[0]['rgb'].shape[-2:])}; "
        f"points: pixels with depth <= {MAX_DEPTH:g} m; CPU: {cpu_summary()}"
    )
    print("\n| model | --max-uncertainty | points kept | RMSE of kept points (m) | kept points > 1 m off |")
    print("|---|---|---|---|---|")
    for i, w in enumerate(args.weights):
        preds = _predictions(w, held)
        print("\n".join(table(w, preds)))
        if args.picture is not None and i == 0:
            picture(args.picture, w, *preds[args.scene], args.picture_limit)
    if args.picture is not None:
        print(f"\npicture: {args.picture} ({args.weights[0]}, scene {held.names[args.scene]})")


if __name__ == "__main__":
    main()
