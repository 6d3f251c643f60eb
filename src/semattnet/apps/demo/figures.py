"""The demo's pictures: per-scene comparison and branch panels, training curves, and ``viewer.html``."""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from semattnet.apps.demo.recipe import DEMO_MODELS, LABELS, REFERENCE_KEY, Trained
from semattnet.apps.experiment import HeldOut, score_held_out
from semattnet.viz.depth import colorize_depth, error_map
from semattnet.viz.panels import branch_panel, save_panel
from semattnet.viz.viewer import ViewerFrame, write_viewer

__all__ = ["STAGES_SHOWN", "figures", "viewer"]

#: Training stages whose curves the report shows, in order (a run writes those it has).
STAGES_SHOWN = ("backbone", "refine_init", "full")


def _shown_methods(preds: dict[str, dict[str, np.ndarray]]) -> tuple[str, ...]:
    return tuple(m for m in ("classical", "two_branch", "semattnet", REFERENCE_KEY) if m in preds)


def _intrinsics(sample: Mapping[str, object]) -> np.ndarray | None:
    """The scene's (3, 3) intrinsics, None when the sample has none (NaN-filled)."""
    K = sample.get("K")
    K = None if K is None else np.asarray(K, dtype=np.float64).reshape(3, 3)
    return K if K is not None and np.isfinite(K).all() else None


def viewer(out: Path, held: HeldOut, preds: dict[str, dict[str, np.ndarray]], trained: Trained, count: int) -> Path:
    """``viewer.html`` for the first ``count`` held-out scenes: every method, SemAttNet's intermediates."""
    frames = []
    for n in held.names[:count]:
        smp = held.samples[held.names.index(n)]
        frames.append(
            ViewerFrame(
                name=n,
                rgb=smp["rgb"].permute(1, 2, 0).numpy().astype(np.uint8),
                sparse=smp["sparse"][0].numpy(),
                depths={m: preds[m][n] for m in _shown_methods(preds)},
                semantic=smp["semantic"].permute(1, 2, 0).numpy().astype(np.uint8),
                gt=held.gts[n],
                outputs=trained.outputs["semattnet"][n],
                outputs_of="semattnet",
                K=_intrinsics(smp),
                cloud_of="semattnet",
                note="shadowed" if held.shadowed[n] else "unshadowed",
            )
        )
    return write_viewer(out, frames, LABELS, title="SemAttNet demo: held-out scenes", back=("report", "report.html"))


def figures(
    pictures: Path, held: HeldOut, preds: dict[str, dict[str, np.ndarray]], trained: Trained
) -> list[tuple[str, str]]:
    """The report's (caption, path) figures: panels of a shadowed and an unshadowed scene, training curves."""
    names, shadowed = held.names, held.shadowed
    shown = [next(n for n in names if shadowed[n]), next(n for n in names if not shadowed[n])]
    out: list[tuple[str, str]] = []
    for n in shown:
        out += _scene_figures(pictures, held, n, preds, trained.outputs["semattnet"][n])
    return out + _curve_figures(pictures, trained.runs)


def _scene_figures(
    pictures: Path,
    held: HeldOut,
    n: str,
    preds: dict[str, dict[str, np.ndarray]],
    semattnet_outputs: dict[str, np.ndarray],
) -> list[tuple[str, str]]:
    """Scene ``n``'s panels: SemAttNet's intermediate depths, and depth and error map per method."""
    smp, gt = held.samples[held.names.index(n)], held.gts[n]
    rgb = smp["rgb"].permute(1, 2, 0).numpy().astype(np.uint8)
    sem = smp["semantic"].permute(1, 2, 0).numpy().astype(np.uint8)
    kind = "shadowed" if held.shadowed[n] else "unshadowed"
    branch_panel(
        pictures / f"branches_{kind}.png", rgb, sem, smp["sparse"][0].numpy(), semattnet_outputs, gt, columns=4
    )
    tiles = [("RGB", rgb), ("ground truth", colorize_depth(gt))]
    for method in _shown_methods(preds):
        rmse = score_held_out({n: preds[method][n]}, held)["all"]["rmse_mm"]
        short = (
            "SemAttNet reference (shipped, first seed)" if method == REFERENCE_KEY else LABELS[method].split(" (")[0]
        )
        tiles.append((f"{short}: depth, RMSE {rmse / 1000:.2f} m", colorize_depth(preds[method][n])))
        tiles.append((f"{short}: error", error_map(preds[method][n], gt)))
    save_panel(tiles, pictures / f"compare_{kind}.png", columns=2)
    return [
        (
            f"Comparison on a held-out {kind} scene: depth and KITTI error map per method "
            "(error colours: blue = small, red = large)",
            f"pictures/compare_{kind}.png",
        ),
        (
            f"SemAttNet's intermediate depths on the {kind} scene (the model trained by this run, seed of the "
            "first row): colour-, semantic- and depth-guided branches, their fusion, the CSPN++ refinement and "
            "the branch confidences",
            f"pictures/branches_{kind}.png",
        ),
    ]


def _curve_figures(pictures: Path, runs: dict[str, Path]) -> list[tuple[str, str]]:
    """Copy each model's training curves (per stage, where written) beside the pictures."""
    out = []
    for key, label, _ in DEMO_MODELS:
        for stage in STAGES_SHOWN:
            curve = runs[key] / stage / "curves.png"
            if curve.is_file():
                target = pictures / f"curves_{key}_{stage}.png"
                shutil.copyfile(curve, target)
                out.append((f"Training curves: {label}, {stage.replace('_', ' ')} stage", f"pictures/{target.name}"))
    return out
