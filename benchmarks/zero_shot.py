"""The zero-shot benchmark: every method on frames of rigs it never saw, the bundled real KITTI frame first.

One command (from the repository root, the package installed):

    python benchmarks/zero_shot.py --out zero-shot-run

Rows (``--methods``): the classical completion, the generalist's anchor alone (its non-learned part), the
shipped street-trained demo references, the generalists (``semattnet-generalist``,
``semattnet-half-generalist``, ``semattnet-rt-generalist``, ``semattnet-rt-half-generalist``) and, with ``--adapted
LABEL=WEIGHTS``, weights that ``semattnet adapt`` made from a generalist on the real frame's own sensors (no ground
truth read). Columns:

* ``real``: the bundled KITTI frame (drive 0035, frame 5), cameras 02 and 03, its own scan projected as
  ``predict --kitti-raw`` does, scored against the official annotated map; no semantic map (the fallback);
* held-out world scenes (:func:`semattnet.evaluation.zero_shot.world_frames`, seeds training never draws) of
  each kind and sparse pattern: ``street`` with ``lidar``, ``points``, ``depthcam``; ``indoor`` with ``points``
  (500: the NYU protocol), ``depthcam`` and ``lidar``;
* a sparsity sweep: streets seen by 8 to 128 LiDAR beams, rooms given 50 to 5000 random points.

Metrics per cell, means over its frames: RMSE and MAE (mm), iRMSE and iMAE (1/km), REL, and the uncertainty's
2-sigma coverage (%) and AUSE. Writes ``OUT/results.json`` (atomic), ``OUT/table.md`` and ``OUT/zero-shot.png``;
``--docs PAGE`` puts the table between the page's ``<!-- zero-shot:begin -->`` / ``end`` markers and the plot
beside it as ``docs/zero-shot.png``. ``--frames N`` sets the world frames per cell (default 6), ``--quick`` runs
two per cell and no sweep (what a test runs).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from semattnet._utils.atomic import atomic_path
from semattnet.evaluation.zero_shot import BenchFrame, DepthMethod, mean_scores, real_frames, score, world_frames
from semattnet.synthetic.world import HELDOUT_CELLS

DEFAULT_METHODS = (
    "classical",
    "anchor",
    "semattnet-demo-ref-seed0",
    "semattnet-demo-ref-robust-seed0",
    "semattnet-rt-md-demo-seed0",
    "semattnet-generalist",
    "semattnet-rt-generalist",
    "semattnet-rt-half-generalist",
    "semattnet-half-generalist",
)
#: (column, kind, pattern, options of the pattern): the held-out world cells.
CELLS = HELDOUT_CELLS
SWEEP = tuple(("street/beams", "street", "lidar", {"beams": b}) for b in (8, 16, 32, 64, 128)) + tuple(
    ("indoor/points", "indoor", "points", {"count": n}) for n in (50, 200, 500, 2000, 5000)
)
SIZE = (256, 512)  # the world cells' image size (H, W): one size, so every method sees the same pixels


def _cell_frames(cells: tuple, count: int) -> dict[str, list[BenchFrame]]:
    out: dict[str, list[BenchFrame]] = {}
    for column, kind, pattern, options in cells:
        key = column + "".join(f"-{v}" for v in options.values()) if column.endswith(("beams", "points")) else column
        out[key] = list(world_frames(kind, pattern, count, SIZE, **options))
    return out


def method(name: str, device: str = "cpu") -> DepthMethod:
    """``classical``, ``anchor`` (the generalist's anchor alone: :func:`~semattnet.models.generalist.prepare_inputs`)
    or weights (a registered name or a file), as a :data:`DepthMethod`; the fallback semantic map for models that
    read one."""
    if name == "classical":
        from semattnet.baselines.classical import ClassicalCompleter

        classical = ClassicalCompleter()

        def run_classical(rgb: np.ndarray, sparse: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
            c = classical(rgb, sparse)
            return c.depth, c.uncertainty

        return run_classical
    if name == "anchor":  # the generalist's non-learned anchor alone
        from semattnet.models.generalist import prepare_inputs

        def run_anchor(rgb: np.ndarray, sparse: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
            t = torch.from_numpy(np.ascontiguousarray(sparse, dtype=np.float32))[None, None]
            return prepare_inputs(torch.zeros(1, 3, *sparse.shape), t).anchor[0, 0].numpy(), None

        return run_anchor
    from semattnet.inference.backends import EngineSpec
    from semattnet.inference.completer import load_completer
    from semattnet.palette import unknown_map

    completer = load_completer(name, EngineSpec(device=device), progress=False)

    def run_model(rgb: np.ndarray, sparse: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        semantic = unknown_map(*rgb.shape[:2]) if completer.needs_semantic else None
        c = completer(rgb, sparse, semantic)
        return c.depth, c.uncertainty

    return run_model


def run(methods: list[str], frames: dict[str, list[BenchFrame]], log: Callable[[str], None]) -> dict:
    """``{method: {column: mean scores}}`` and the time each method took."""
    results: dict[str, dict[str, dict[str, float]]] = {}
    for name in methods:
        t0 = time.perf_counter()
        complete = method(name)
        results[name] = {}
        for column, items in frames.items():
            rows = []
            for f in items:
                depth, unc = complete(f.rgb, f.sparse)
                rows.append(score(depth, f.gt, unc))
            results[name][column] = mean_scores(rows)
        log(f"{name}: {time.perf_counter() - t0:.0f} s")
    return results


def table(results: dict, columns: list[str], metric: str = "rmse_mm") -> str:
    """A markdown table: one row per method, one column per cell, ``metric``."""
    head = "| method | " + " | ".join(columns) + " |\n|---|" + "---:|" * len(columns) + "\n"
    lines = []
    for name, cells in results.items():
        best = {c: min(r[c][metric] for r in results.values() if c in r) for c in columns}
        vals = [cells[c][metric] if c in cells else float("nan") for c in columns]
        fmt = ".3f" if metric == "rel" else ".0f"
        txt = [f"**{v:{fmt}}**" if v == best[c] else f"{v:{fmt}}" for v, c in zip(vals, columns, strict=True)]
        lines.append(f"| `{name}` | " + " | ".join(txt) + " |")
    return head + "\n".join(lines) + "\n"


def coverage_table(results: dict, columns: list[str]) -> str:
    """The uncertainty's 2-sigma coverage (%) per cell, for the methods whose uncertainty is calibrated (the
    generalists'); the goal is 90-99 in every cell."""
    head = "| method | " + " | ".join(columns) + " |\n|---|" + "---:|" * len(columns) + "\n"
    lines = []
    for name, cells in results.items():
        if "generalist" not in name:
            continue
        vals = [cells.get(c, {}).get("coverage_2sigma_pct", float("nan")) for c in columns]
        lines.append(f"| `{name}` | " + " | ".join(f"{v:.1f}" for v in vals) + " |")
    return head + "\n".join(lines) + "\n"


def real_table(results: dict) -> str:
    """The real frame: every metric per camera, one row per method."""
    keys = ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km", "coverage_2sigma_pct", "ause_rmse")
    keys += ("gate_kept_pct", "gate_rmse_mm")
    head = "| method | camera | RMSE mm | MAE mm | iRMSE 1/km | iMAE 1/km | 2-sigma coverage % | AUSE |"
    head += " kept by `--max-uncertainty 10%` | their RMSE mm |\n|---|---|" + "---:|" * len(keys) + "\n"
    rows = []
    for name, cells in results.items():
        for cam in ("real/cam02", "real/cam03"):
            r = cells[cam]
            rows.append(
                f"| `{name}` | {cam[-2:]} | " + " | ".join(f"{r.get(k, float('nan')):.2f}" for k in keys) + " |"
            )
    return head + "\n".join(rows) + "\n"


def plot(results: dict, path: Path) -> None:
    """Left: RMSE on the real frame per method; right: RMSE against LiDAR beams (streets) and points (rooms)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    names = list(results)
    real = [np.mean([results[n][c]["rmse_mm"] for c in ("real/cam02", "real/cam03")]) / 1000 for n in names]
    axes[0].barh(names, real, color=["0.5" if n == "classical" else "C0" for n in names])
    for y, v in enumerate(real):
        axes[0].text(v, y, f" {v:.2f}", va="center", fontsize=8)
    if "classical" in names:
        axes[0].axvline(real[names.index("classical")], color="0.3", ls=":")
    axes[0].set(xlabel="RMSE (m), real KITTI frame, mean of cameras 02/03", xlim=(0, max(real) * 1.15))
    for ax, prefix, label, scale in (
        (axes[1], "street/beams-", "LiDAR beams (streets)", "linear"),
        (axes[2], "indoor/points-", "random points (rooms)", "log"),
    ):
        for n in names:
            cols = [c for c in results[n] if c.startswith(prefix)]
            if cols:
                xs = [int(c.removeprefix(prefix)) for c in cols]
                ax.plot(xs, [results[n][c]["rmse_mm"] / 1000 for c in cols], marker="o", label=n)
        ax.set(xscale="log", yscale=scale, xlabel=label, ylabel="RMSE (m), held-out world scenes")
    if axes[2].get_lines():
        axes[2].legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def _docs(page: Path, text: str) -> None:
    body = page.read_text()
    begin, end = "<!-- zero-shot:begin -->", "<!-- zero-shot:end -->"
    if begin not in body or end not in body:
        raise SystemExit(f"{page}: no {begin} / {end} markers")
    head, rest = body.split(begin, 1)
    page.write_text(head + begin + "\n" + text + rest[rest.index(end) :])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--methods", default=",".join(DEFAULT_METHODS))
    ap.add_argument("--adapted", action="append", default=[], metavar="NAME=WEIGHTS")
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--docs", type=Path, default=None)
    ap.add_argument("--sample", type=Path, default=Path("tests/data/kitti_sample"))
    args = ap.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    adapted = dict(a.split("=", 1) for a in args.adapted)
    count = 2 if args.quick else args.frames
    frames = {f"real/cam0{f.name[-1]}": [f] for f in real_frames(args.sample)}
    frames |= _cell_frames(CELLS, count)
    if not args.quick:
        frames |= _cell_frames(SWEEP, max(2, count // 2))
    results = run(methods + list(adapted.values()), frames, print)
    for label, weights in adapted.items():
        results[label] = results.pop(weights)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "results.json") as tmp:
        tmp.write_text(json.dumps({"results": results, "frames_per_cell": count}, indent=1))
    cells = [c for c in frames if not c.startswith("real") and "-" not in c.split("/")[1]]
    text = "Real KITTI frame, zero-shot:\n\n" + real_table(results) + "\nHeld-out world scenes, RMSE mm:\n\n"
    text += (
        table(results, cells)
        + "\nREL on the rooms (lower is better):\n\n"
        + table(results, [c for c in cells if c.startswith("indoor")], "rel")
        + "\nThe generalists' 2-sigma coverage % on the world cells (over the pixels with a depth; goal 90-99):\n\n"
        + coverage_table(results, cells)
    )
    (args.out / "table.md").write_text(text)
    plot(results, args.out / "zero-shot.png")
    if args.docs is not None:
        _docs(args.docs, text)
        (args.docs.parent.parent / "zero-shot.png").write_bytes((args.out / "zero-shot.png").read_bytes())
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
