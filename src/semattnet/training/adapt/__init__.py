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
from collections.abc import Callable, Collection
from pathlib import Path

from semattnet.data.frames import FrameSource
from semattnet.inference.semantic import SemanticMaps
from semattnet.training.adapt.config import LOSS_TERMS, AdaptConfig
from semattnet.training.adapt.run import FINAL, LOG, RUN_FILES, STATE, Adapter, AdaptResult, run_files

__all__ = [
    "FINAL",
    "LOG",
    "LOSS_TERMS",
    "RUN_FILES",
    "STATE",
    "AdaptConfig",
    "AdaptResult",
    "Adapter",
    "adapt",
    "prepare_run_folder",
]


def prepare_run_folder(out: str | os.PathLike[str], overwrite: bool = False) -> bool:
    """A new run refuses a folder that already holds one (``FileExistsError`` naming the file). With ``overwrite`` it
    removes nothing: returns whether there is an earlier run, which the new one replaces at its first state (the
    earlier run's files, :data:`RUN_FILES`, stay until then)."""
    existing = run_files(Path(out))
    if existing and not overwrite:
        raise FileExistsError(
            f"{out} already holds an adaptation run ({Path(out) / existing[0]} exists); pass "
            "--resume to continue it or --overwrite to start over"
        )
    return bool(existing)


def adapt(
    cfg: AdaptConfig,
    source: FrameSource,
    semantic: SemanticMaps | None = None,
    *,
    resume: bool = False,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
    asked: Collection[str] = (),
) -> AdaptResult:
    """Fine-tune ``cfg.weights`` on ``source``'s frames (``semantic``: where missing semantic maps come from; default
    the fallback map). A new run needs an empty ``cfg.out`` (or ``overwrite``: the earlier run is replaced once the
    new one has its first state); ``resume`` continues the run there exactly (``asked``: the fields of ``cfg`` the
    caller chose, refused when they differ from the run's). No input may lie inside ``cfg.out``; the folder is locked
    while the run writes into it. Returns where it ended (:class:`AdaptResult`); the weights are
    ``cfg.out/adapted.safetensors``. Launched by ``torchrun``, joins (and then leaves) its process group: one DDP
    replica per process."""
    from semattnet._utils import distributed as dist_utils
    from semattnet._utils.lock import FolderLock
    from semattnet._utils.outputs import check_no_input_overlap
    from semattnet._utils.run_folder import finish_replacements, refuse_inputs_inside

    weights = cfg.weights if cfg.weights and Path(cfg.weights).exists() else None
    check_no_input_overlap([*source.inputs(), weights], out_dir=cfg.out)
    refuse_inputs_inside(cfg.out, [*source.inputs(), weights])
    lock = FolderLock(cfg.out)
    try:
        if dist_utils.launch_rank() == 0:  # before any process reads the folder (a resume: its state)
            lock.acquire()
            finish_replacements(Path(cfg.out), run_files)  # a replacement a kill cut short, committed or not
        replaces = False
        if not resume:  # rank 0 checks the folder; its error reaches every rank
            dist_utils.init_distributed(dist_utils.process_device(cfg.device))  # a resumed run: its state's device
            replaces = dist_utils.on_main(prepare_run_folder, cfg.out, overwrite)
        return Adapter(cfg, source, semantic, resume=resume, log=log, asked=asked, replaces=replaces).run()
    finally:
        lock.release()
        dist_utils.cleanup()
