"""The training loop: the paper's stages, DDP, AMP, exact resume.

A :class:`Trainer` runs one stage of :class:`~semattnet.training.config.TrainConfig`. It checkpoints
atomically (``last.pt`` at every save, ``best.pt`` on the best validation RMSE, the last
``keep_last`` periodic ones), and ``resume=True`` continues from ``last.pt`` exactly, mid-epoch
too: model, optimiser, scheduler, grad scaler, RNG states and the position in the epoch's data
order are restored (data order and augmentation are functions of (seed, epoch, index)).
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset, Subset

from semattnet._errors import DataError, InputError
from semattnet._utils import distributed as dist_utils
from semattnet._utils.atomic import atomic_path
from semattnet._utils.extras import optional
from semattnet._utils.progress import progress
from semattnet._utils.run_folder import commit_stage, drop_stages, finish_replacements, open_stage
from semattnet.data.datasets import get_dataset
from semattnet.data.kitti.splits import KittiDepthCompletion
from semattnet.data.transforms import EvalTransform
from semattnet.evaluation.protocols import protocol_metrics
from semattnet.models.backbone import SemAttNetBackbone
from semattnet.models.layers import set_gradient_checkpointing
from semattnet.models.registry import build_model, model_config
from semattnet.models.rt import SemAttNetRT, SemAttNetRTBackbone
from semattnet.models.semattnet import SemAttNet
from semattnet.training.checkpointing import set_activation_checkpointing
from semattnet.training.config import TrainConfig
from semattnet.training.reference import ParamGroup, make_adam, our_step
from semattnet.training.state import TRAIN_FORMAT, ResumeState, RngStates, TrainResult, TrainState, read_train_state
from semattnet.training.train_folder import RUN_FILES, prepare_run_folder, run_files, truncate_log, write_log_row
from semattnet.training.validation import validate_model
from semattnet.weights.checkpoint import load_checkpoint, load_weights
from semattnet.weights.gate import DIGEST_KEY, tensor_digest

if TYPE_CHECKING:
    from torch.utils.tensorboard import SummaryWriter

__all__ = ["RUN_FILES", "TrainResult", "Trainer", "prepare_run_folder", "train"]

_SYNC_BN_CPU = (
    "sync_bn needs CUDA (NCCL); set sync_bn=false: on CPU each process keeps its own BatchNorm "
    "statistics (a multi-process CPU run averages gradients, not BatchNorm statistics)"
)


def _atomic_torch_save(obj: object, path: Path) -> None:
    with atomic_path(path) as tmp:
        torch.save(obj, tmp)


def _unwrap(model: nn.Module) -> SemAttNet | SemAttNetBackbone | SemAttNetRT | SemAttNetRTBackbone:
    inner = model.module if isinstance(model, nn.parallel.DistributedDataParallel) else model
    assert isinstance(inner, SemAttNet | SemAttNetBackbone | SemAttNetRT | SemAttNetRTBackbone)  # _build_model's
    return inner


@dataclass
class _Position:
    epoch: int = 0
    batch: int = 0  # next batch index within the epoch
    step: int = 0  # optimiser steps done in total
    best: float = math.inf


class Trainer:
    """One training stage. ``Trainer(cfg).fit()`` (or ``resume=True`` to continue)."""

    def __init__(
        self, cfg: TrainConfig, resume: bool = False, log: Callable[[str], None] = print, replaces: bool = False
    ) -> None:
        self.replaces = replaces  # OUT holds an earlier run: it stays whole until this one's first state
        self.device = dist_utils.process_device(cfg.device)
        self.distributed = dist_utils.init_distributed(self.device)
        self.main = dist_utils.is_main()
        self._log = log
        self.out = Path(cfg.out)
        self.ckpt_dir = self.out / "checkpoints"
        state = None
        if resume:
            state = read_train_state(self.ckpt_dir / "last.pt")
            # The run may have moved: keep writing where it is now.
            cfg = TrainConfig.from_dict(state["train_config"] | {"out": str(cfg.out)})
        self.cfg = cfg
        if not cfg.data:
            raise InputError("no data root given (--data)")
        if cfg.sync_bn and self.device.type != "cuda":
            raise InputError(_SYNC_BN_CPU)
        self.pos = _Position()
        torch.manual_seed(cfg.seed)
        random.seed(cfg.seed)
        np.random.seed(cfg.seed)
        self.model = self._build_model(init_weights=state is None)
        self._build_data()
        self._build_optimisation()
        if self.distributed:  # DDP, optionally with SyncBatchNorm
            self.model = dist_utils.wrap_model(self.model, self.device, cfg.sync_bn)
        if state is not None:
            self._restore(state)
        self.tb = self._open_run_folder() if self.main else None
        if state is not None and self.main:
            truncate_log(self.out / "log.csv", self.pos.step)

    # ----------------------------------------------------------------------------- setup
    def _build_data(self) -> None:
        """The training set, its resumable sampler and loader, and the validation loader."""
        cfg = self.cfg
        self.semantic_root = self._segmented() if cfg.segment else cfg.semantic_root
        self.train_set = get_dataset(cfg.dataset).dataset(
            cfg.data,
            "train",
            train=True,
            seed=cfg.seed,
            raw_root=cfg.raw_root,
            semantic_root=self.semantic_root,
            config=cfg,
        )
        self.sampler = dist_utils.ResumableSampler(len(self.train_set), seed=cfg.seed)
        # The loader's own generator: starting an epoch's iterator must not draw from the global RNG,
        # or a resumed run (which starts a new iterator mid-epoch) would diverge from an uninterrupted one.
        self.loader_rng = torch.Generator()
        self.loader = DataLoader(
            self.train_set,
            batch_size=cfg.batch_size,
            sampler=self.sampler,
            generator=self.loader_rng,
            num_workers=cfg.workers,
            drop_last=True,
            pin_memory=self.device.type == "cuda",
            persistent_workers=False,
        )
        if len(self.loader) == 0:
            raise DataError(
                f"{len(self.train_set)} training frames per process is fewer than one batch of {cfg.batch_size}"
            )
        self.val_loader = self._val_loader()

    def _build_optimisation(self) -> None:
        """Adam over the stage's parameter groups, the learning-rate schedule and the AMP grad scaler."""
        cfg = self.cfg
        assert cfg.epochs is not None and cfg.patience is not None  # TrainConfig fills them from the stage
        self.optimizer = make_adam(self._param_groups(), self.device, betas=cfg.betas, weight_decay=cfg.weight_decay)
        self.scheduler: torch.optim.lr_scheduler.LambdaLR | torch.optim.lr_scheduler.ReduceLROnPlateau
        if cfg.lr_schedule == "cosine":  # per step, to zero at the last step
            total = cfg.max_steps or cfg.epochs * len(self.loader)
            self.scheduler = torch.optim.lr_scheduler.LambdaLR(
                self.optimizer, lambda step: 0.5 * (1.0 + math.cos(math.pi * min(step, total) / total))
            )
        else:  # the paper's: x0.1 when the validation RMSE stops improving
            self.scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
                self.optimizer, mode="min", factor=0.1, patience=cfg.patience
            )
        self.scaler = torch.amp.GradScaler(self.device.type, enabled=cfg.amp == "fp16")

    def _open_run_folder(self) -> SummaryWriter | None:
        """Create the run folder (a stage inside it while the run replaces an earlier one, until its first state:
        :mod:`semattnet._utils.run_folder`), write ``config.json``; a TensorBoard writer if tensorboard is installed."""
        if self.replaces:
            self.out = open_stage(Path(self.cfg.out))
            self.ckpt_dir = self.out / "checkpoints"
        self.out.mkdir(parents=True, exist_ok=True)
        self.cfg.save(self.out / "config.json")
        return self._tensorboard()

    def _tensorboard(self) -> SummaryWriter | None:
        if optional("tensorboard") is None:  # optional: pip install 'semattnet[tensorboard]'
            return None
        from torch.utils.tensorboard import SummaryWriter

        return SummaryWriter(str(self.out / "tensorboard"))

    def log(self, msg: str) -> None:
        if self.main:
            self._log(msg)

    def _build_model(self, init_weights: bool) -> nn.Module:
        cfg = self.cfg
        arch = model_config(cfg.model).replace(refine=cfg.stage != "backbone")
        model = build_model(
            config=arch,
            width=cfg.width,
            branches=cfg.branches,
            fusion=cfg.fusion,
            refinement_mode=cfg.refinement_mode,
            palette=get_dataset(cfg.dataset).palette,
        )
        if isinstance(model, SemAttNet | SemAttNetRT):  # the refine-init and full stages
            if init_weights and not cfg.init:
                raise InputError(f"stage {cfg.stage!r} starts from the previous stage's checkpoint: pass --init PATH")
            if init_weights and cfg.init:
                ckpt = load_checkpoint(cfg.init)
                is_backbone = not any(k.startswith("backbone.") for k in ckpt.state_dict)
                load_weights(model.backbone if is_backbone else model, ckpt)
                self.log(f"initialised from {cfg.init} ({'backbone' if is_backbone else 'full model'})")
            if cfg.stage == "refine-init":
                for p in model.backbone.parameters():
                    p.requires_grad_(False)
            if cfg.refinement_mode == "authors":  # the aliasing bypasses them: they cannot learn
                for p in (*model.dimhalf_s2.parameters(), *model.att_12.parameters()):
                    p.requires_grad_(False)
        elif cfg.init:
            load_weights(model, load_checkpoint(cfg.init))
        elif cfg.depth_head_init is not None and isinstance(model, SemAttNetBackbone | SemAttNetRTBackbone):
            model.init_depth_heads(*cfg.depth_head_init)
        if cfg.grad_checkpointing:
            set_gradient_checkpointing(model, True)
        if cfg.activation_checkpointing:
            set_activation_checkpointing(model, True)
        return model.to(self.device)

    def _param_groups(self) -> list[ParamGroup]:
        model, cfg = self.model, self.cfg
        trainable = [(n, p) for n, p in model.named_parameters() if p.requires_grad]
        if cfg.stage != "full":
            return [{"params": [p for _, p in trainable], "lr": cfg.lr}]
        backbone = [p for n, p in trainable if n.startswith("backbone.")]
        head = [p for n, p in trainable if not n.startswith("backbone.")]
        return [{"params": backbone, "lr": cfg.lr}, {"params": head, "lr": cfg.head_lr}]

    def _val_loader(self) -> DataLoader | None:
        cfg = self.cfg
        if not cfg.val_split:
            return None
        if cfg.dataset == "kitti-dc":
            ds: Dataset = KittiDepthCompletion(
                cfg.data,
                cfg.val_split,
                cfg.raw_root,
                cfg.semantic_root,
                transform=EvalTransform(tuple(cfg.crop)),  # type: ignore[arg-type]
            )
        else:  # the protocol's frames, padded to multiples of 32 (validate_model crops them back)
            ds = get_dataset(cfg.dataset).dataset(cfg.data, cfg.val_split, semantic_root=self.semantic_root)
        if cfg.val_max_frames:
            ds = Subset(ds, range(min(cfg.val_max_frames, len(ds))))  # type: ignore[arg-type]
        return DataLoader(
            ds,
            batch_size=1,
            sampler=dist_utils.ShardSampler(len(ds)),  # type: ignore[arg-type]
            num_workers=cfg.workers,
            generator=torch.Generator().manual_seed(cfg.seed),
        )

    def _segmented(self) -> str:
        """``--segment``: the cached maps of the train and validation frames (rank 0 segments the missing)."""
        from semattnet.segmentation.datasets import segment_split

        cfg = self.cfg
        splits = ("train", *([cfg.val_split] if cfg.val_split and cfg.val_split != "train" else []))
        return str(
            dist_utils.on_main(
                segment_split, cfg.dataset, cfg.data, splits, str(cfg.segment), str(self.device), log=self.log
            )
        )

    def _set_train_mode(self) -> None:
        self.model.train()
        if self.cfg.stage == "refine-init":  # frozen backbone: its BN statistics stay fixed too
            model = _unwrap(self.model)
            assert isinstance(model, SemAttNet | SemAttNetRT)  # refine-init trains the refined model
            model.backbone.eval()

    # ----------------------------------------------------------------------------- state
    def _state(self) -> TrainState:
        rng: RngStates = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}
        if torch.cuda.is_available():
            rng["cuda"] = torch.cuda.get_rng_state_all()
        return {
            "format": TRAIN_FORMAT,
            "model": _unwrap(self.model).state_dict(),
            "config": _unwrap(self.model).config.to_dict(),  # what load_checkpoint/load_model read
            "train_config": self.cfg.to_dict(),
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "scaler": self.scaler.state_dict(),
            "rng": rng,
            "epoch": self.pos.epoch,
            "batch_in_epoch": self.pos.batch,
            "global_step": self.pos.step,
            "best_metric": self.pos.best,
        }

    def _restore(self, state: ResumeState) -> None:
        load_weights(_unwrap(self.model), state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.scheduler.load_state_dict(state["scheduler"])
        self.scaler.load_state_dict(state["scaler"])
        rng = state["rng"]
        torch.set_rng_state(rng["torch"])
        np.random.set_state(rng["numpy"])
        random.setstate(rng["python"])
        if "cuda" in rng and torch.cuda.is_available():
            torch.cuda.set_rng_state_all(rng["cuda"])
        self.pos = _Position(state["epoch"], state["batch_in_epoch"], state["global_step"], state["best_metric"])
        self.log(f"resumed at epoch {self.pos.epoch}, batch {self.pos.batch}, step {self.pos.step}")

    def save(self, best: bool = False, periodic: bool = False) -> None:
        """Write ``last.pt`` (and ``best.pt`` / a numbered copy) atomically; rank 0 only."""
        if not self.main:
            return
        state: dict[str, object] = dict(self._state())
        state[DIGEST_KEY] = tensor_digest(state)  # load_checkpoint verifies it (resume, --init, predict, ...)
        _atomic_torch_save(state, self.ckpt_dir / "last.pt")
        if best:
            _atomic_torch_save(state, self.ckpt_dir / "best.pt")
        if periodic and self.cfg.keep_last > 0:
            _atomic_torch_save(state, self.ckpt_dir / f"step-{self.pos.step:08d}.pt")
            kept = sorted(self.ckpt_dir.glob("step-*.pt"))
            for old in kept[: -self.cfg.keep_last]:
                old.unlink()
        if self.replaces:
            self._replace_earlier_run()

    def _replace_earlier_run(self) -> None:
        """The stage holds a whole state: it replaces the earlier run (committed first, then moved into place,
        the earlier run's other files removed); from now on the run writes into its folder."""
        if self.tb is not None:
            self.tb.close()
        stage, self.out = self.out, Path(self.cfg.out)
        commit_stage(stage, self.out, run_files)
        self.ckpt_dir, self.replaces = self.out / "checkpoints", False
        self.tb = self._tensorboard()

    # ----------------------------------------------------------------------------- loop
    def _write_row(self, row: Mapping[str, float | str]) -> None:
        if self.main:
            write_log_row(self.out / "log.csv", row, self.tb)

    def validate(self) -> dict[str, float] | None:
        if self.val_loader is None:
            return None
        metrics = partial(protocol_metrics, self.cfg.dataset)
        result = validate_model(self.model, self.val_loader, self.device, self.cfg.amp, metrics).compute()
        row: dict[str, float | str] = {"epoch": self.pos.epoch, "step": self.pos.step, "split": self.cfg.val_split}
        self._write_row(row | result)
        self.log(
            f"epoch {self.pos.epoch}: {self.cfg.val_split} RMSE {result['rmse_mm']:.1f} mm, "
            f"MAE {result['mae_mm']:.1f} mm"
        )
        return result

    def fit(self) -> TrainResult:
        """Run (or finish) the stage; returns the final position and last validation result."""
        last_val: dict[str, float] | None = None
        assert self.cfg.epochs is not None  # TrainConfig fills it from the stage
        while self.pos.epoch < self.cfg.epochs:
            finished_epoch = self._train_epoch()
            if not finished_epoch:  # max_steps reached mid-epoch
                self.save()
                break
            self.pos.epoch, self.pos.batch = self.pos.epoch + 1, 0
            best, last_val = self._end_of_epoch(last_val)
            self.save(best=best, periodic=True)
            if self.cfg.max_steps and self.pos.step >= self.cfg.max_steps:
                break
        self._check_sync()
        if self.tb is not None:
            self.tb.close()
        if self.main:
            from semattnet.viz.curves import plot_training_curves

            plot_training_curves(self.out / "log.csv", self.out / "curves.png")
        return TrainResult(epoch=self.pos.epoch, step=self.pos.step, best_rmse_mm=self.pos.best, val=last_val)

    def _train_epoch(self) -> bool:
        """Train from the current position to the end of the epoch (or ``max_steps``); True if it ended."""
        cfg, epoch = self.cfg, self.pos.epoch
        assert cfg.batch_size is not None  # TrainConfig fills it from the stage
        self.sampler.set_epoch(epoch)
        self.train_set.set_epoch(epoch)
        self.sampler.start_at(self.pos.batch * cfg.batch_size)
        self.loader_rng.manual_seed(cfg.seed * 1_000_003 + epoch)  # worker seeds: a function of (seed, epoch)
        weight = cfg.branch_weight(epoch)
        self._set_train_mode()
        bar = progress(
            total=len(self.loader),
            initial=self.pos.batch,
            desc=f"epoch {epoch}",
            enabled=self.main,
            unit="batch",
            dynamic_ncols=True,
        )
        loss = float("nan")
        with bar:
            for batch in self.loader:
                loss = self._step(batch, weight)
                bar.update(1)
                bar.set_postfix(loss=f"{loss:.3f}", lr=f"{self.optimizer.param_groups[0]['lr']:.2e}")
                if self.pos.step % cfg.log_every == 0 or self.pos.batch == len(self.loader):
                    lr = self.optimizer.param_groups[0]["lr"]
                    row: dict[str, float | str] = {
                        "epoch": epoch,
                        "step": self.pos.step,
                        "split": "train",
                        "loss": loss,
                        "lr": lr,
                    }
                    self._write_row(row)
                if cfg.save_every and self.pos.step % cfg.save_every == 0:
                    self.save(periodic=True)
                if cfg.max_steps and self.pos.step >= cfg.max_steps:
                    break
        if bar.disable:  # no bar (not a terminal): one line for the epoch instead
            self.log(
                f"epoch {epoch}: batch {self.pos.batch}/{len(self.loader)}, step {self.pos.step}, "
                f"loss {loss:.3f}, lr {self.optimizer.param_groups[0]['lr']:.2e}"
            )
        return self.pos.batch >= len(self.loader)

    def _step(self, batch: Mapping[str, torch.Tensor], branch_weight: float) -> float:
        """One optimiser step on ``batch`` (eq. 14 loss, AMP-aware); returns the loss."""
        loss = our_step(
            self.model,
            self.optimizer,
            batch,
            self.device,
            branch_weight,
            self.cfg.amp,
            self.scaler if self.scaler.is_enabled() else None,
            self.cfg.loss,
        )
        if isinstance(self.scheduler, torch.optim.lr_scheduler.LambdaLR):  # cosine: per step
            self.scheduler.step()
        self.pos.batch += 1
        self.pos.step += 1
        return loss.item()

    def _end_of_epoch(self, last_val: dict[str, float] | None) -> tuple[bool, dict[str, float] | None]:
        """Validate when due, step the plateau schedule; returns (new best?, last validation result)."""
        cfg = self.cfg
        if self.val_loader is None or not (self.pos.epoch % cfg.val_every == 0 or self.pos.epoch == cfg.epochs):
            return False, last_val
        last_val = self.validate()
        rmse = last_val["rmse_mm"] if last_val else math.inf
        if isinstance(self.scheduler, torch.optim.lr_scheduler.ReduceLROnPlateau):
            self.scheduler.step(rmse)
        best = rmse < self.pos.best
        self.pos.best = min(self.pos.best, rmse)
        return best, last_val

    def _check_sync(self) -> None:
        """Across ranks, every parameter must be identical after training (DDP's contract)."""
        if not self.distributed:
            return
        total = dist_utils.check_in_sync(_unwrap(self.model))
        self.log(f"{dist_utils.world_size()} ranks in sync (parameter checksum {total:.6e})")


def train(
    cfg: TrainConfig, resume: bool = False, log: Callable[[str], None] = print, overwrite: bool = False
) -> TrainResult:
    """Run one stage; joins/leaves the process group when launched by torchrun.

    Without ``resume`` the run folder must not hold a run yet (``overwrite`` starts over, replacing the earlier run
    once the new one has its first state: :func:`prepare_run_folder`); with ``resume`` the run continues exactly from
    ``last.pt``.
    """
    from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs

    # the run folder is never (inside) the data, nor is the --init checkpoint one of the run's files
    check_no_input_overlap([cfg.data or None, cfg.raw_root, cfg.semantic_root], out_dir=cfg.out)
    init = cfg.init if cfg.init and Path(cfg.init).exists() else None
    check_outputs(
        [
            ("--data", cfg.data or None),
            ("--raw-root", cfg.raw_root),
            ("--semantic-root", cfg.semantic_root),
            ("--init", init),
        ],
        [Output("--out", cfg.out, "folder")],
    )
    check_no_input_overlap(
        [cfg.init if cfg.init and Path(cfg.init).exists() else None], out_files=[Path(cfg.out) / f for f in RUN_FILES]
    )
    if dist_utils.launch_rank() == 0:
        finish_replacements(Path(cfg.out), run_files)  # a replacement a kill cut short, committed or not
    replaces = not resume and prepare_run_folder(cfg.out, overwrite)
    try:
        return Trainer(cfg, resume=resume, log=log, replaces=replaces).fit()
    except BaseException:
        drop_stages(Path(cfg.out))  # failed before its first state: the earlier run stays, and nothing of this one
        raise
    finally:
        dist_utils.cleanup()
