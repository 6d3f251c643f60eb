"""Self-supervised adaptation (``semattnet adapt``): fine-tune any weights on a user's own frames, from any source
``predict`` reads, with no ground truth: sparse-depth self-supervision (hidden LiDAR points), photometric
consistency with the frames' other views (a stereo partner) and edge-aware smoothness. The result is a normal
checkpoint (``predict --weights RUN/adapted.safetensors``).

    >>> from semattnet.training.adapt import AdaptConfig, adapt                          # doctest: +SKIP
    >>> from semattnet.data.sources import RawDriveSource                                # doctest: +SKIP
    >>> source = RawDriveSource("kitti_raw/2011_09_26/2011_09_26_drive_0035_sync")       # doctest: +SKIP
    >>> adapt(AdaptConfig("semattnet-demo-ref-seed0", "runs/adapt", steps=200), source)  # doctest: +SKIP
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from semattnet.data.frames import FrameSource
from semattnet.inference.semantic import SemanticMaps
from semattnet.training.adapt.config import LOSS_TERMS, AdaptConfig
from semattnet.training.adapt.run import FINAL, LOG, RUN_FILES, STATE, Adapter, AdaptResult

__all__ = ["FINAL", "LOG", "LOSS_TERMS", "RUN_FILES", "STATE", "AdaptConfig", "AdaptResult", "Adapter", "adapt",
           "prepare_run_folder"]  # fmt: skip


def prepare_run_folder(out: str | os.PathLike[str], overwrite: bool = False) -> None:
    """A new run refuses a folder that already holds one (``FileExistsError`` naming the file); with ``overwrite``
    it removes the run's own files (:data:`RUN_FILES`) only."""
    existing = [Path(out) / f for f in RUN_FILES if (Path(out) / f).exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{out} already holds an adaptation run ({existing[0]} exists); pass --resume to "
                              "continue it or --overwrite to start over")  # fmt: skip
    for path in existing:
        path.unlink()


def adapt(cfg: AdaptConfig, source: FrameSource, semantic: SemanticMaps | None = None, *, resume: bool = False,
          overwrite: bool = False, log: Callable[[str], None] = print) -> AdaptResult:  # fmt: skip
    """Fine-tune ``cfg.weights`` on ``source``'s frames (``semantic``: where missing semantic maps come from; default
    the fallback map). A new run needs an empty ``cfg.out`` (or ``overwrite``); ``resume`` continues the run there
    exactly. Returns where it ended (:class:`AdaptResult`); the weights are ``cfg.out/adapted.safetensors``.
    Launched by ``torchrun``, joins (and then leaves) its process group: one DDP replica per process."""
    from semattnet._utils import distributed as dist_utils
    from semattnet._utils.outputs import check_no_input_overlap

    weights = cfg.weights if cfg.weights and Path(cfg.weights).exists() else None
    check_no_input_overlap([*source.inputs(), weights], out_dir=cfg.out)
    try:
        if not resume:  # rank 0 checks (and clears) the folder; its error reaches every rank
            dist_utils.init_distributed(dist_utils.process_device(cfg.device))  # a resumed run: its state's device
            dist_utils.on_main(prepare_run_folder, cfg.out, overwrite)
        return Adapter(cfg, source, semantic, resume=resume, log=log).run()
    finally:
        dist_utils.cleanup()
