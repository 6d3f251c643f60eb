"""Training the generalist (:mod:`semattnet.models.generalist`) on the randomised synthetic world.

One recipe for both shipped generalists (``semattnet-generalist`` and ``semattnet-rt-generalist``):

* a **bank** of world frames (:func:`semattnet.synthetic.world.make_world_frame`: streets and rooms, random
  rigs, image sizes and sparse patterns), written once as ``.npz`` files and shared by every run
  (:func:`write_bank`);
* random crops of :attr:`GeneralistTrainConfig.crop` (any frame size), horizontal flips, and for a share of the
  crops the no-segmenter fallback map instead of the semantic map;
* a scale-free loss: the mean absolute error of the log depth over the pixels with truth, for the generalist's
  output ``D`` and (weight 0.1) for the network's unbounded depth ``D_n``, so that the network keeps learning
  where the bound holds ``D`` back;
* Adam with a cosine schedule; ``last.pt`` written atomically every :attr:`GeneralistTrainConfig.save_every`
  steps and read back by ``resume`` (the step, model, optimiser, schedule and random state), so a killed run
  goes on where it stopped.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet.models.generalist import Generalist

__all__ = ["GeneralistTrainConfig", "load_bank", "sample_batch", "train_generalist", "write_bank"]


@dataclass(frozen=True)
class GeneralistTrainConfig:
    """What :func:`train_generalist` runs.

    Attributes:
        model: a registered generalist (``semattnet_generalist`` or ``semattnet_rt_generalist``).
        bank: the folder of world frames (:func:`write_bank`).
        out: the run's folder (``last.pt``, ``log.jsonl``).
        steps, batch, crop, lr: the optimisation (crop: (height, width), multiples of 32).
        fallback_share: the share of crops given the no-segmenter fallback map.
        width: the model's width (None: the registered one).
        save_every: steps between checkpoints.
        seed: the crops' and the initialisation's seed.
        init: weights of the same network without an anchor (a registered name or a file) to start from
            (:func:`init_from_plain`), or None.
    """

    model: str = "semattnet_rt_generalist"
    bank: str = "world-bank"
    out: str = "generalist-run"
    steps: int = 2000
    batch: int = 8
    crop: tuple[int, int] = (160, 256)
    lr: float = 2e-3
    fallback_share: float = 0.5
    width: float | None = None
    save_every: int = 100
    seed: int = 0
    init: str | None = None

    def __post_init__(self) -> None:
        from semattnet.models.registry import model_config

        m = 32 * model_config(self.model).work_scale  # the network's multiple, at its own resolution
        if self.crop[0] % m or self.crop[1] % m:
            raise InputError(f"crop must be multiples of {m} for {self.model}, got {self.crop}")
        if self.steps < 1 or self.batch < 1:
            raise InputError(f"steps and batch must be >= 1, got {self.steps}, {self.batch}")
        if not 0.0 <= self.fallback_share <= 1.0:
            raise InputError(f"fallback_share must be in [0, 1], got {self.fallback_share}")


def write_bank(
    out: str | Path, count: int, split: str = "train", start: int = 0, log: Callable[[str], None] = print
) -> Path:
    """Write world frames ``start`` .. ``count - 1`` of ``split`` as ``out/{split}_{index:05d}.npz`` (frames already
    there are kept: a killed run goes on)."""
    from semattnet.synthetic.world import make_world_frame, world_seed

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for i in range(start, count):
        path = out / f"{split}_{i:05d}.npz"
        if path.exists():
            continue
        f = make_world_frame(world_seed(split, i))
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(
                fh, rgb=f.rgb, semantic=f.semantic, sparse=f.sparse, gt=f.gt, K=f.K, kind=f.kind, pattern=f.pattern
            )
        if (i + 1) % 50 == 0:
            log(f"bank {split}: {i + 1}/{count} frames ({time.perf_counter() - t0:.0f} s)")
    return out


def load_bank(folder: str | Path, split: str = "train") -> list[dict[str, np.ndarray]]:
    """Every frame of ``split`` in ``folder``, in order."""
    paths = sorted(Path(folder).glob(f"{split}_*.npz"))
    if not paths:
        raise InputError(f"{folder}: no {split}_*.npz world frames (write them with write_bank)")
    frames = []
    for p in paths:
        with np.load(p) as z:
            frames.append({k: z[k] for k in z.files})
    return frames


def _crop(frame: dict[str, np.ndarray], crop: tuple[int, int], rng: np.random.Generator) -> list[np.ndarray]:
    """rgb, semantic, sparse, gt cropped to ``crop`` (frames smaller than it are edge-padded, sparse and gt with
    zeros), flipped left-right half the time."""
    h, w = frame["sparse"].shape
    ch, cw = crop
    arrays = [frame["rgb"], frame["semantic"], frame["sparse"], frame["gt"]]
    if h < ch or w < cw:
        ph, pw = max(0, ch - h), max(0, cw - w)
        arrays = [
            np.pad(a, ((0, ph), (0, pw)) + ((0, 0),) * (a.ndim - 2), mode="edge" if a.ndim == 3 else "constant")
            for a in arrays
        ]
        h, w = arrays[2].shape
    y, x = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
    out = [a[y : y + ch, x : x + cw] for a in arrays]
    if rng.random() < 0.5:
        out = [a[:, ::-1] for a in out]
    return out


def sample_batch(
    bank: list[dict[str, np.ndarray]], cfg: GeneralistTrainConfig, rng: np.random.Generator
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """A batch of crops: rgb, semantic (B, 3, H, W) 0..255, sparse, gt (B, 1, H, W) metres. Crops without a
    sparse point are drawn again."""
    from semattnet.palette import unknown_map

    items: list[list[np.ndarray]] = []
    while len(items) < cfg.batch:
        rgb, sem, sparse, gt = _crop(bank[int(rng.integers(len(bank)))], cfg.crop, rng)
        if (sparse > 0).sum() < 8 or (gt > 0).sum() < 64:
            continue
        if rng.random() < cfg.fallback_share:
            sem = unknown_map(*cfg.crop)
        items.append([rgb, sem, sparse, gt])

    def stack(k: int, image: bool) -> torch.Tensor:
        t = torch.from_numpy(np.stack([np.ascontiguousarray(it[k]) for it in items]).astype(np.float32))
        return t.permute(0, 3, 1, 2) if image else t[:, None]

    return stack(0, True), stack(1, True), stack(2, False), stack(3, False)


def generalist_loss(
    model: Generalist, rgb: torch.Tensor, semantic: torch.Tensor, sparse: torch.Tensor, gt: torch.Tensor
) -> torch.Tensor:
    """Mean |log D - log gt| plus 0.1 mean |log D_n - log gt| over the pixels with truth (module docstring)."""
    inputs = model.prepare(rgb, sparse, semantic)
    out = model.net(inputs.rgb, inputs.semantic, inputs.depth)
    net_depth = out.depth.float() * inputs.scale
    depth = model.refine(net_depth, inputs)
    net_depth = model.to_full(net_depth, inputs)
    valid = gt > 0
    log_gt = torch.log(gt[valid])
    main = (torch.log(depth[valid].clamp_min(1e-3)) - log_gt).abs().mean()
    aux = (torch.log(net_depth[valid].clamp_min(1e-3)) - log_gt).abs().mean()
    return main + 0.1 * aux


def init_from_plain(model: Generalist, weights: str, log: Callable[[str], None] = print) -> None:
    """Start ``model.net`` from the weights of the same network trained without an anchor: every tensor of the
    same name and shape is copied; each input convolution that reads one more depth channel (the anchor) gets
    the old weights with a zero column for the anchor, inserted after the sparse depth's column (the colour and
    semantic stems read ``[image; sparse; anchor; ...]``, the depth stem ``[sparse; anchor; ...]``)."""
    from semattnet.weights import from_pretrained

    loaded = from_pretrained(weights, map_location="cpu")
    plain = (loaded.net if isinstance(loaded, Generalist) else loaded).state_dict()  # a generalist: go on from it
    own = model.net.state_dict()
    copied, widened = 0, 0
    for name, t in own.items():
        old = plain.get(name)
        if old is None:
            continue
        if old.shape == t.shape:
            own[name] = old
            copied += 1
        elif t.dim() == 4 and old.dim() == 4 and t.shape[1] == old.shape[1] + 1 and t.shape[0] == old.shape[0]:
            at = 1 if "depth" in name else 4
            zero = torch.zeros_like(old[:, :1])
            own[name] = torch.cat((old[:, :at], zero, old[:, at:]), dim=1)
            widened += 1
    model.net.load_state_dict(own)
    log(
        f"init from {weights}: {copied} tensors copied, {widened} input convolutions widened, "
        f"{len(own) - copied - widened} kept"
    )


def _state(
    step: int,
    model: Generalist,
    opt: torch.optim.Optimizer,
    sched: torch.optim.lr_scheduler.LRScheduler,
    rng: np.random.Generator,
) -> dict[str, object]:
    """Everything ``resume`` reads back: the step, model, optimiser, schedule and random state."""
    return {
        "step": step,
        "model": model.state_dict(),
        "optimizer": opt.state_dict(),
        "scheduler": sched.state_dict(),
        "rng": rng.bit_generator.state,
    }


def train_generalist(
    cfg: GeneralistTrainConfig, resume: bool = False, log: Callable[[str], None] = print
) -> Generalist:
    """Train ``cfg.model`` on the bank (module docstring); returns the trained model (also in ``out/last.pt``)."""
    from semattnet.models.registry import build_model

    torch.manual_seed(cfg.seed)
    model = build_model(cfg.model) if cfg.width is None else build_model(cfg.model, width=cfg.width)
    if not isinstance(model, Generalist):
        raise InputError(f"{cfg.model}: not a generalist (a registered model with anchor='classical')")
    model.init_depth_heads()
    if cfg.init is not None:
        init_from_plain(model, cfg.init, log)
    bank = load_bank(cfg.bank)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.5 * (1 + math.cos(math.pi * min(s, cfg.steps) / cfg.steps))
    )
    rng, step = np.random.default_rng(cfg.seed), 0
    if resume and (out / "last.pt").exists():
        state = torch.load(out / "last.pt", map_location="cpu", weights_only=True)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        sched.load_state_dict(state["scheduler"])
        rng.bit_generator.state = state["rng"]
        step = int(state["step"])
        log(f"resumed at step {step}")
    (out / "config.json").write_text(json.dumps(dataclasses.asdict(cfg), indent=1))
    model.train()
    t0, running, since = time.perf_counter(), 0.0, 0
    while step < cfg.steps:
        loss = generalist_loss(model, *sample_batch(bank, cfg, rng))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 5.0)
        opt.step()
        sched.step()
        step += 1
        running += loss.item()
        since += 1
        if step % cfg.save_every == 0 or step == cfg.steps:
            with atomic_path(out / "last.pt") as tmp:
                torch.save(_state(step, model, opt, sched, rng), tmp)
            rate, mean = (time.perf_counter() - t0) / since, running / since
            with open(out / "log.jsonl", "a") as fh:
                fh.write(json.dumps({"step": step, "loss": mean, "s_per_step": rate}) + "\n")
            log(f"step {step}/{cfg.steps}: loss {mean:.4f} ({rate:.2f} s/step)")
            t0, running, since = time.perf_counter(), 0.0, 0
    return model.eval()


#: Held-out world frames from this index on calibrate the uncertainty; the benchmark scores those before it.
CALIBRATION_FIRST = 1000


def calibrate_uncertainty(
    model: Generalist,
    frames: int = 24,
    pixels: int = 240_000,
    log: Callable[[str], None] = print,
    size: tuple[int, int] | None = None,
) -> tuple[float, float, float]:
    """Fit ``model.calibration`` (:func:`~semattnet.models.generalist.fit_calibration`: in each held-out cell,
    91-99 % of the errors within 2 sigma) on ``frames`` held-out world frames shared out over the cells of
    :data:`~semattnet.synthetic.world.HELDOUT_CELLS` (at least one each), from :data:`CALIBRATION_FIRST` on, at
    their own random sizes (``size``: all at that (H, W)), half of them with the fallback semantic map, whole
    frames as inference sees them; sets the buffer and returns ``(k, f, g)``."""
    from semattnet.models.generalist import fit_calibration
    from semattnet.synthetic.world import HELDOUT_CELLS

    model.eval()
    rng = np.random.default_rng(0)
    per_cell = max(1, -(-frames // len(HELDOUT_CELLS)))
    parts: list[list[np.ndarray]] = [[] for _ in range(5)]  # raw, depth, far, error, cell
    for c, (_, kind, pattern, options) in enumerate(HELDOUT_CELLS):
        for i in range(per_cell):
            raw, depth, far, error = _pixels(model, CALIBRATION_FIRST + i, (kind, pattern, options), size, i % 2 == 0)
            take = rng.permutation(raw.size)[: pixels // (per_cell * len(HELDOUT_CELLS))]
            for part, values in zip(parts, (raw, depth, far, error, np.full(raw.size, c)), strict=True):
                part.append(values[take])
    raw_t, depth_t, far_t, error_t, cell_t = (torch.from_numpy(np.concatenate(p)).double() for p in parts)
    k, floor, far_term = fit_calibration(raw_t, depth_t, far_t, error_t, cell_t)
    model.calibration.copy_(torch.tensor([k, floor, far_term]))
    log(
        f"uncertainty calibrated on {per_cell} held-out world frames in each of {len(HELDOUT_CELLS)} cells: "
        f"sigma = {k:.3f} u + {floor:.4f} depth + {far_term:.2f} depth * distance / height"
    )
    return k, floor, far_term


def _pixels(
    model: Generalist,
    index: int,
    cell: tuple[str, str, dict[str, int]],
    size: tuple[int, int] | None,
    fallback: bool,
) -> tuple[np.ndarray, ...]:
    """``(u, D, r / H, D - truth)`` over the pixels with truth and a depth of one held-out world frame, cropped to
    the network's multiple (no padding), completed as inference completes it."""
    from semattnet.palette import unknown_map
    from semattnet.synthetic.world import make_world_frame, world_seed

    kind, pattern, options = cell
    frame = make_world_frame(world_seed("heldout", index), kind=kind, pattern=pattern, size=size, **options)
    h, w = (n // 32 * 32 for n in frame.sparse.shape)
    semantic = unknown_map(h, w) if fallback else frame.semantic[:h, :w]
    rgb, sem = (_image(a[:h, :w]) for a in (frame.rgb, semantic))
    sparse = torch.from_numpy(np.ascontiguousarray(frame.sparse[:h, :w], dtype=np.float32))[None, None]
    with torch.no_grad():
        inputs = model.prepare(rgb, sparse, sem)
        out = model.finish(model.net(inputs.rgb, inputs.semantic, inputs.depth), inputs, uncertainty=False)
        raw, far = model.uncertainty_terms(out, inputs)
    depth = out.depth[0, 0].numpy()
    valid = (frame.gt[:h, :w] > 0) & (depth > 0)  # a pixel left without depth has no uncertainty to judge
    return raw[0, 0].numpy()[valid], depth[valid], far[0, 0].numpy()[valid], (depth - frame.gt[:h, :w])[valid]


def _image(a: np.ndarray) -> torch.Tensor:
    """(H, W, 3) colours -> (1, 3, H, W) float32."""
    return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1)[None]


def finish_generalist(
    model: Generalist,
    cfg: GeneralistTrainConfig,
    frames: int = 24,
    log: Callable[[str], None] = print,
    size: tuple[int, int] | None = None,
) -> Path:
    """Calibrate the trained model's uncertainty (:func:`calibrate_uncertainty`) and write it packed (int8 per
    output channel, as the shipped weights are: 127 levels per sign, 63 for the paper's model, whose 5.7 M
    parameters then ship under 5 MB) to ``out/MODEL.safetensors.gz``."""
    from semattnet.weights.packed import save_packed

    calibrate_uncertainty(model, frames=frames, log=log, size=size)
    info = {"recipe": dataclasses.asdict(cfg), "calibration": model.calibration.tolist()}
    levels = 127 if model.config.realtime else 63
    return save_packed(model, Path(cfg.out) / f"{cfg.model}.safetensors.gz", info, levels=levels)
