"""The out-of-the-box demo: synthetic data -> train -> evaluate against baselines -> report.

``semattnet demo`` generates KITTI-like scenes in the "realistic" style (LiDAR failures on dark
and glossy paint and glass, markings and posters that change colour but not depth, grey cars
before grey walls; half of them with a hard shadow band), trains a width-reduced SemAttNet and the
two-branch ablation (no semantic branch) for the same number of optimiser steps (the paper's
protocol; ``DemoSettings.equal_steps``), once per training seed (two by default), through the
real training engine (backbone stage, then the full model with CSPN++),
scores both on held-out scenes with the KITTI metrics beside the sparse input, a classical
non-learned completion and the shipped reference checkpoints (SemAttNet trained once, longer, on
other scenes, one file per training seed: :mod:`semattnet.apps.demo.reference`;
``semattnet demo --train-reference`` rebuilds them), and writes ``report.md`` and
``report.html`` with the table (each learned model's mean and every seed), a plain verdict per
comparison, per-branch panels, error maps, training curves and the sparsification curves of each
method's per-pixel uncertainty (:mod:`semattnet.apps.demo.uncertainty`), ``viewer.html`` (the interactive
viewer of the held-out scenes, :mod:`semattnet.viz.viewer`) and ``results.json``. No download;
3.7 minutes measured on a quiet 2-core AVX-512 CPU (see docs/guides/demo.md).

``results.json`` (schema ``semattnet.demo.results/2``; units: RMSE and MAE in mm, iRMSE and
iMAE in 1/km, as KITTI's leaderboard)::

    {
      "schema": "semattnet.demo.results/2",
      "units": {"rmse": "mm", "mae": "mm", "irmse": "1/km", "imae": "1/km"},
      "seeds": [0, 1],                    # training seeds; the scenes come from settings.seed
      "methods": {                        # sparse, classical, two_branch, semattnet, reference
        "semattnet": {
          "label": "SemAttNet (...)",
          "all": {"rmse": .., "mae": .., "irmse": .., "imae": .., "images": 16},  # mean over seeds
          "shadowed": {...}, "unshadowed": {...},                                  # same keys
          "per_seed": {"0": {"all": {...}, "shadowed": {...}, "unshadowed": {...}}}
        }, ...
      },
      "steps": {"semattnet": {"backbone": N, "full": M}, "two_branch": {...}},  # per seed
      "wall_seconds": {"total": s, "models": {"semattnet": s, "two_branch": s}},  # train + complete, all seeds
      "machine": {"cpu": "model name", "cores": n, "torch": "2.x", "python": "3.x",
                  "platform": "...", "device": "cpu", "torch_threads": n},
      "held_out": {"frames": n, "shadowed": n},
      "settings": {...},                  # DemoSettings as a dict
      "recipe": {"live": ["how the live models train, how that differs from the paper", ...],
                 "reference": ["how the reference was trained, its deviations", ...]},
      "reference": {"label": .., "seeds": [0, 1], "storage": .., "command": .., "recipe": {...},
                    "recipe_notes": [...],
                    "files": [{"seed": 0, "file": .., "bytes": n, "sha256": .., "train_seconds": s,
                               "trained_on": "cpu", "own_validation": {"reference": {...}, "classical": {...}}}]},
      "comparisons": {"semattnet_better_than": {"classical": {"rmse": true, ...}, "two_branch": {...}},
                      "reference_better_than": {...},   # the shipped reference, same form
                      "verdicts": ["SemAttNet (mean of seeds 0, 1) vs ...: better on ...; not better on ..."]},
      "uncertainty": {                    # classical, semattnet, two_branch, reference: the per-pixel
        "semattnet": {                    # uncertainty's sparsification (semattnet.apps.demo.uncertainty)
          "label": .., "ause_rmse": .., "aurg_rmse": .., "ause_mae": .., "aurg_mae": ..,  # mean over seeds
          "per_seed": {"0": {"ause_rmse": .., ...}, "1": {...}},
          "curves": {"rmse_curve": [100 values], "rmse_oracle": [...], "mae_curve": [...], "mae_oracle": [...]}
        }, ...
      }
    }

The baselines do not depend on the training seed: their ``per_seed`` entries repeat the same
numbers. The reference's ``per_seed`` is keyed by its own training seeds (``reference.seeds``).
Without a reference file (or ``DemoSettings(reference=False)``) the
``reference`` method, block and comparison are absent.

Modules: :mod:`~semattnet.apps.demo.recipe` (settings, models, step plan, training),
:mod:`~semattnet.apps.demo.reference` (the shipped checkpoint), :mod:`~semattnet.apps.demo.results`
(means, comparisons, ``results.json``), :mod:`~semattnet.apps.demo.figures` (pictures, viewer),
:mod:`~semattnet.apps.demo.uncertainty` (AUSE / AURG of the uncertainty), :mod:`~semattnet.apps.demo.run`
(:func:`run_demo`).
"""

from semattnet.apps.demo.recipe import DemoSettings
from semattnet.apps.demo.results import COMPARED, comparisons
from semattnet.apps.demo.run import DemoResult, run_demo, train_reference_run

__all__ = ["COMPARED", "DemoResult", "DemoSettings", "comparisons", "run_demo", "train_reference_run"]
