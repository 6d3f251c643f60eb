"""The adaptation loop: fine-tune weights on a source's own frames with the self-supervised losses, no ground truth.

A run folder holds ``checkpoints/last.pt`` (the resumable state: model, optimiser, schedule, grad scaler, random
generators, step; written atomically every ``save_every`` steps and at the end; a normal checkpoint that
``predict --weights`` reads, as ``train``'s ``last.pt``), ``adapted.safetensors`` (the final weights) and
``log.json`` (the losses of every step, the held-out metrics, the frames skipped). ``resume=True`` continues from
``last.pt`` exactly: a run killed mid-way and resumed ends with the weights of an uninterrupted run, bit for bit.

Launched by ``torchrun``, every process trains a DDP replica (gradients averaged) on its own random draws (frames,
crops, hidden points: the seed and the rank); rank 0 alone logs and writes the run folder, the state holding every
rank's generator, and at the end the ranks' parameters are checked identical. With ``freeze_bn=False`` the
BatchNorm layers become SyncBatchNorm (statistics over every rank's crops), which needs CUDA.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import torch

from semattnet._errors import InputError
from semattnet._utils import distributed as dist_utils
from semattnet._utils.atomic import atomic_path, full_disk_named
from semattnet._utils.device import autocast
from semattnet._utils.progress import progress
from semattnet._utils.run_folder import replace_run
from semattnet.data.frames import FrameSource
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.inference.feed import FrameFault
from semattnet.inference.semantic import SemanticMaps
from semattnet.training.adapt.batch import AdaptBatch, crop_size, make_batch
from semattnet.training.adapt.config import AdaptConfig
from semattnet.training.adapt.losses import hide_points, photometric_loss, smoothness_loss, sparse_loss
from semattnet.training.adapt.model import TrainingCompleter, final_depth, set_train_mode
from semattnet.training.adapt.pool import FramePool
from semattnet.training.adapt.resume import FORMAT, AdaptState, read_state, restore, resumed_config
from semattnet.training.reference import make_adam
from semattnet.weights.checkpoint import Checkpoint, save_safetensors
from semattnet.weights.gate import DIGEST_KEY, tensor_digest

__all__ = ["FINAL", "LOG", "RUN_FILES", "STATE", "AdaptResult", "AdaptState", "Adapter", "read_state", "run_files"]

STATE, FINAL, LOG = "checkpoints/last.pt", "adapted.safetensors", "log.json"
#: What a run writes into its folder (``overwrite`` replaces exactly these, at the new run's first state).
RUN_FILES = (STATE, FINAL, LOG)


def run_files(folder: Path) -> list[str]:
    """The files of a run (:data:`RUN_FILES`) that ``folder`` holds."""
    return [f for f in RUN_FILES if (folder / f).exists() or (folder / f).is_symlink()]


@dataclass(frozen=True)
class AdaptResult:
    """Where a run ended: ``step``, the final ``weights`` file, the ``frames`` trained on, the ``skipped`` ones,
    the last held-out ``metrics`` (None without ground truth) and the mean ``seconds_per_step`` of this process."""

    step: int
    weights: Path
    frames: int
    skipped: tuple[FrameFault, ...] = ()
    metrics: dict[str, float] | None = None
    seconds_per_step: float = math.nan
    losses: dict[str, float] = field(default_factory=dict)


class Adapter:
    """One adaptation run of ``cfg`` on ``source`` (``semantic``: the filler of missing semantic maps; default the
    fallback map); ``resume`` continues the run in ``cfg.out`` (``asked``: the fields of ``cfg`` the caller chose,
    refused when they differ from the run's). ``replaces``: ``cfg.out`` holds an earlier run, which this one replaces
    at its first state (:func:`~semattnet._utils.run_folder.replace_run`). ``Adapter(...).run()`` trains to
    ``cfg.steps``."""

    def __init__(
        self,
        cfg: AdaptConfig,
        source: FrameSource,
        semantic: SemanticMaps | None = None,
        resume: bool = False,
        log: Callable[[str], None] = print,
        *,
        asked: Collection[str] = (),
        replaces: bool = False,
    ) -> None:
        from semattnet.weights.hub import from_pretrained

        self.out, self.replaces = Path(cfg.out), replaces
        state = read_state(self.out / STATE) if resume else None
        if state is not None:  # the run's own options; it may have moved
            cfg = resumed_config(self.out / STATE, state, cfg, asked)
        self.cfg, self.device = cfg, dist_utils.process_device(cfg.device)
        self.distributed = dist_utils.init_distributed(self.device)
        self.main = dist_utils.is_main()
        self.log = log if self.main else _silent
        _check_amp(cfg.amp, self.device)
        _check_processes(cfg, self.device, state)
        # a resumed run starts from its own state (a normal checkpoint): the first weights may have moved since
        self.model = from_pretrained(self.out / STATE if state is not None else cfg.weights, map_location=self.device)
        self.completer = TrainingCompleter(self.model, self.device)
        maps = (semantic or SemanticMaps()).bind(self.completer)
        maps.check_palette(self.completer, source)
        with warnings.catch_warnings():
            if not self.main:  # the same frames, the same warnings (the fallback map): rank 0 says them
                warnings.simplefilter("ignore")
            self.pool = FramePool(source, maps, cfg.on_error, cfg.gt_frames if cfg.gt_every else 0, self.log)
        self.crop = crop_size(cfg.crop, self.pool.sizes)
        if min(self.crop) < 32:
            raise InputError(f"crop: the frames ({self.pool.sizes[0][1]}x{self.pool.sizes[0][0]}) are smaller than 32")
        self.net = self._wrap() if self.distributed else self.model  # what the steps run
        self.optimizer = make_adam(self.model.parameters(), self.device, lr=cfg.lr)
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer, lambda step: 0.5 * (1.0 + math.cos(math.pi * min(step, cfg.steps) / cfg.steps))
        )
        self.scaler = torch.amp.GradScaler(self.device.type, enabled=cfg.amp == "fp16")
        self.rng = torch.Generator().manual_seed(dist_utils.rank_seed(cfg.seed, dist_utils.rank()))
        self.step, self.rows, self.metrics = 0, list[dict[str, float]](), list[dict[str, float]]()
        if state is not None:
            self._restore(state)
        self._no_views_said = False

    def _wrap(self) -> torch.nn.Module:
        """The model in DDP (SyncBatchNorm where BatchNorm trains); ``self.model`` stays the bare one. The losses
        read the final depth alone, which some layers may not reach (under the authors' refinement, ``att_12`` and
        ``dimhalf_s2``): DDP looks for the parameters without a gradient."""
        net = dist_utils.wrap_model(self.model, self.device, sync_bn=not self.cfg.freeze_bn, find_unused=True)
        self.model = net.module  # SyncBatchNorm replaced the model's BatchNorm layers in place
        return net

    # ----------------------------------------------------------------------------- state
    def _restore(self, state: AdaptState) -> None:
        """Optimiser, schedule, scaler, generator and step (the weights came with the model, from the state), each
        checked first (:func:`~semattnet.training.adapt.resume.restore`)."""
        restore(self.out / STATE, state, (self.optimizer, self.scheduler, self.scaler), self.rng, dist_utils.rank())
        self.step = state["step"]
        logged = _read_log(self.out / LOG)
        self.rows, self.metrics = _rows(logged, "steps", self.step), _rows(logged, "metrics", self.step)
        self.log(f"resumed at step {self.step} of {self.cfg.steps}")

    def save(self) -> None:
        """The log, then the resumable state, each atomically; rank 0 writes them (collective: every rank's
        generator). In this order a run killed in between still has the log of every step of its state (a resumed
        run drops the rows after it). The first state of a run that replaces an earlier one goes through a stage
        folder: the earlier run's files stay until it is complete."""
        rngs = [s for _, s in dist_utils.gather_rows([(dist_utils.rank(), self.rng.get_state())], key=lambda r: r[0])]
        if not self.main:
            return
        if self.replaces:
            replace_run(self.out, run_files, partial(self._write_state, rngs=rngs))
            self.replaces = False
        else:
            self._write_state(self.out, rngs)

    def _write_state(self, folder: Path, rngs: list[torch.Tensor]) -> None:
        """The log, then the resumable state, into ``folder`` (the run folder, or the stage replacing it)."""
        self._write_log(folder)
        model_config = getattr(self.model, "config", None)
        state: dict[str, object] = {
            "format": FORMAT,
            "model": self.model.state_dict(),
            "config": model_config.to_dict() if model_config is not None else None,
            "adapt_config": self.cfg.to_dict(),
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "scaler": self.scaler.state_dict(),
            "rng": rngs,
            "step": self.step,
        }
        state[DIGEST_KEY] = tensor_digest(state)
        path = folder / STATE
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp, full_disk_named(path):
            torch.save(state, tmp)  # torch's writer says a full disk as a RuntimeError: one line naming the file

    def _write_log(self, folder: Path) -> None:
        faults = [{"name": f.name, "status": f.status, "reason": f.reason} for f in self.pool.faults]
        doc = {
            "config": self.cfg.to_dict(),
            "crop": list(self.crop),
            "frames": len(self.pool.names),
            "held_out": self.pool.held_out,
            "skipped": faults,
            "steps": self.rows,
            "metrics": self.metrics,
        }
        with atomic_path(folder / LOG, suffix=".json") as tmp:
            tmp.write_text(json.dumps(doc, indent=1) + "\n")

    # ----------------------------------------------------------------------------- loop
    def run(self) -> AdaptResult:
        """Train from the current step to ``cfg.steps``; the final weights to ``adapted.safetensors``."""
        cfg, times = self.cfg, []
        self.out.mkdir(parents=True, exist_ok=True)
        bar = progress(
            total=cfg.steps, initial=self.step, desc="adapt", unit="step", dynamic_ncols=True, enabled=self.main
        )
        with bar:
            while self.step < cfg.steps:
                start = time.perf_counter()
                row = self._step()
                times.append(time.perf_counter() - start)
                self.rows.append(row)
                bar.update(1)
                bar.set_postfix(loss=f"{row['loss']:.3f}")
                if bar.disable and (self.step % max(1, cfg.steps // 20) == 0 or self.step == cfg.steps):
                    self.log(f"step {self.step}/{cfg.steps}: loss {row['loss']:.4f}, {times[-1]:.2f} s/step")
                if self.main and cfg.gt_every and self.pool.held_out and self.step % cfg.gt_every == 0:
                    self._held_out_metric()
                if self.step % cfg.save_every == 0 or self.step == cfg.steps:
                    self.save()
        if not times:
            self.save()  # nothing left to do: the log at least
        if self.distributed:
            self.log(
                f"{dist_utils.world_size()} ranks in sync (parameter checksum "
                f"{dist_utils.check_in_sync(self.model):.6e})"
            )
        weights = dist_utils.on_main(self._write_final)
        last = self.metrics[-1] if self.metrics and self.metrics[-1]["step"] == self.step else None
        losses = {k: v for k, v in (self.rows[-1] if self.rows else {}).items() if k not in ("step", "lr")}
        return AdaptResult(
            self.step,
            weights,
            len(self.pool.names),
            tuple(self.pool.faults),
            last,
            sum(times) / len(times) if times else math.nan,
            losses,
        )

    def _write_final(self) -> Path:
        config = getattr(self.model, "config", None)
        ckpt = Checkpoint(self.out / STATE, self.model.state_dict(), "torch", config=config)
        return save_safetensors(ckpt, self.out / FINAL)

    def _step(self) -> dict[str, float]:
        """One optimiser step; the row of the log (``step``, ``loss``, each term, ``lr``)."""
        cfg = self.cfg
        picks = torch.randint(len(self.pool.names), (cfg.batch_size,), generator=self.rng)
        batch = make_batch(self.pool.frames([self.pool.names[int(i)] for i in picks]), self.crop, self.rng)
        share = cfg.hide[0] + (cfg.hide[1] - cfg.hide[0]) * torch.rand(cfg.batch_size, generator=self.rng)
        kept, hidden = hide_points(batch.sparse, share, self.rng) if "sparse" in cfg.losses else (batch.sparse, None)
        set_train_mode(self.net, cfg.freeze_bn)
        dev = self.device
        with autocast(dev, cfg.amp):
            out = self.net(batch.rgb.to(dev), batch.semantic.to(dev), kept.to(dev))
        terms = self._terms(final_depth(out).float(), batch, kept.to(dev), hidden)
        loss = sum(terms.values(), torch.zeros((), device=dev))
        self.optimizer.zero_grad(set_to_none=True)
        if self.scaler.is_enabled():
            self.scaler.scale(loss).backward()
            self.scaler.step(self.optimizer)
            self.scaler.update()
        else:
            loss.backward()
            self.optimizer.step()
        lr = self.optimizer.param_groups[0]["lr"]
        self.scheduler.step()
        self.step += 1
        values = torch.stack([loss.detach(), *(v.detach() for v in terms.values())])
        if self.distributed:  # the mean over the ranks' crops, as the gradients are
            torch.distributed.all_reduce(values)
            values /= dist_utils.world_size()
        return {"step": self.step, **dict(zip(["loss", *terms], values.tolist(), strict=True)), "lr": lr}

    def _terms(
        self, pred: torch.Tensor, batch: AdaptBatch, kept: torch.Tensor, hidden: torch.Tensor | None
    ) -> dict[str, torch.Tensor]:
        """The weighted loss terms asked for (the photometric one only where the batch has other views)."""
        cfg, dev, terms = self.cfg, self.device, {}
        image = batch.rgb.to(dev) / 255.0
        if hidden is not None:
            terms["sparse"] = sparse_loss(pred, kept, hidden.to(dev), cfg.w_kept)
        if "photometric" in cfg.losses and batch.views is not None:
            photo, _ = photometric_loss(image, pred, batch.views.to(dev), cfg.automask)
            terms["photometric"] = cfg.w_photometric * photo
        elif "photometric" in cfg.losses and not self._no_views_said:
            self.log(
                "photometric loss: these frames have no other view (a stereo partner, a posed neighbouring "
                "frame); it is left out"
            )
            self._no_views_said = True
        if "smoothness" in cfg.losses:
            terms["smoothness"] = cfg.w_smooth * smoothness_loss(pred, image)
        return terms

    def _held_out_metric(self) -> None:
        """The KITTI metrics of the current model on the held-out frames (ground truth), logged."""
        metrics = KittiMetrics()
        for frame in self.pool.frames(self.pool.held_out):
            assert frame.gt is not None  # held out for having it
            depth = self.completer(frame.rgb, frame.sparse, frame.semantic).depth
            metrics.update(torch.from_numpy(depth)[None, None], torch.from_numpy(frame.gt)[None, None], [frame.name])
        result = metrics.compute()
        keys = ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km")
        self.metrics.append({"step": self.step, **{k: result[k] for k in keys}})
        self.log(f"step {self.step}: held-out RMSE {result['rmse_mm']:.0f} mm, MAE {result['mae_mm']:.0f} mm")


def _check_amp(amp: str, device: torch.device) -> None:
    """``fp16`` autocast needs CUDA; ``bf16`` on a CPU only with native bfloat16 (else far slower than f32)."""
    from semattnet._utils.cpu import has_native_bf16

    if amp == "fp16" and device.type != "cuda":
        raise InputError(f"amp: fp16 needs a CUDA device, not {device}; use bf16 or none")
    if amp == "bf16" and device.type == "cpu" and not has_native_bf16():
        raise InputError("amp: bf16 on this CPU has no native bfloat16 (slower than f32); use none")


def _check_processes(cfg: AdaptConfig, device: torch.device, state: AdaptState | None) -> None:
    """Several processes: a resumed run needs as many as it ran with (each resumes its own generator), and
    trained BatchNorm is synchronised (SyncBatchNorm), which needs CUDA."""
    world = dist_utils.world_size()
    if state is not None and len(state["rng"]) != world:
        raise InputError(
            f"{Path(cfg.out) / STATE}: the run ran as {len(state['rng'])} process(es), this is {world}; "
            f"resume it with as many (torchrun --nproc_per_node {len(state['rng'])})"
        )
    if world > 1 and not cfg.freeze_bn and device.type != "cuda":
        raise InputError(
            "--train-bn with several processes needs CUDA (SyncBatchNorm across the ranks); on a CPU "
            "leave BatchNorm frozen"
        )


def _silent(line: str) -> None:
    """The log of ranks other than 0."""


def _read_log(path: Path) -> dict[str, list[dict[str, float]]]:
    """A run's ``log.json`` (empty when missing or unreadable: the log is rebuilt from the state's step)."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def _rows(log: dict[str, list[dict[str, float]]], key: str, step: int) -> list[dict[str, float]]:
    """The rows of ``log[key]`` up to ``step`` (a row that is not a mapping with a whole ``step`` is left out)."""
    rows = log.get(key)
    if not isinstance(rows, list):
        return []
    return [r for r in rows if isinstance(r, dict) and type(r.get("step")) is int and r["step"] <= step]
