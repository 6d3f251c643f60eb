"""``semattnet bench``: latency, throughput and peak memory against the naive reference.

Everything is measured in one process, so the ratios hold on any machine:

* **naive reference**: the model as the authors run it: BatchNorm as separate layers and their
  pad-and-sum propagation, one polyphase sub-grid at a time (``propagation_impl="naive"``);
* **ours (float32)**: BatchNorm folded into the convolutions (:func:`fold_batchnorm`) and the
  fused propagation kernel;
* **fast**: the same under bfloat16 (CPU) / float16 (CUDA) autocast, propagation in float32.

Timings (:mod:`semattnet.apps.timing`, whose names this module re-exports) are medians of
``repeats`` runs after a warm-up, synchronised on CUDA. GMACs are counted from the convolutions the
model runs (hooks), and achieved GFLOP/s is compared with the measured peak of one large 3x3
convolution on the same device.
"""

from __future__ import annotations

import functools
import importlib.util
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TypedDict

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.cpu import cpu_summary
from semattnet.inference.backends import engine_entries, optimize_for_inference
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.generalist import Generalist, GeneralistInputs
from semattnet.models.layers import set_gradient_checkpointing
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.propagation import cspn_affinity
from semattnet.models.refinement import run_cspn_stage
from semattnet.models.registry import build_model
from semattnet.training.losses import semattnet_loss

from .timing import conv_peak_gflops, count_macs, fast_mode_dtype, interleaved, peak_memory, timeit

__all__ = [
    "BenchResult",
    "conv_peak_gflops",
    "count_macs",
    "fast_mode_dtype",
    "interleaved",
    "peak_memory",
    "random_frame",
    "run_benchmark",
    "timeit",
]


class BenchRow(TypedDict):
    """One measured row: seconds per run, peak memory, and against its naive reference (None for that one)."""

    what: str
    seconds: float
    peak_mib: float
    speedup: float | None
    max_rel_diff: float | None


@dataclass
class BenchResult:
    device: str
    threads: int
    size: tuple[int, int]
    rows: list[BenchRow] = field(default_factory=list)
    cpu: str = field(default_factory=cpu_summary)
    notes: list[str] = field(default_factory=list)

    def header(self) -> list[str]:
        head = f"{'what':52s} {'seconds':>9s} {'frames/s':>9s} {'peak MiB':>9s} {'x naive':>8s} {'max rel diff':>12s}"
        return [
            f"device {self.device}, {self.threads} threads, {self.size[0]}x{self.size[1]}, batch 1",
            f"CPU: {self.cpu}",
            head,
        ]

    @staticmethod
    def row(r: BenchRow) -> str:
        ratio = f"{r['speedup']:8.2f}" if r.get("speedup") else " " * 8
        diff = f"{r['max_rel_diff']:12.1e}" if r.get("max_rel_diff") is not None else " " * 12
        return f"{r['what']:52s} {r['seconds']:9.3f} {1 / r['seconds']:9.2f} {r['peak_mib']:9.0f} {ratio} {diff}"

    def table(self) -> str:
        return "\n".join(self.header() + [self.row(r) for r in self.rows] + self.notes)

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def random_frame(size: tuple[int, int], device: torch.device) -> dict[str, torch.Tensor]:
    """A fixed random KITTI-like input (seed 0): colours and semantic colours 0..255, 5 % LiDAR pixels up to 80 m."""
    h, w = size
    g = torch.Generator().manual_seed(0)
    x = {
        "rgb": torch.rand(1, 3, h, w, generator=g) * 255,
        "semantic": torch.rand(1, 3, h, w, generator=g) * 255,
        "sparse": torch.rand(1, 1, h, w, generator=g) * 80 * (torch.rand(1, 1, h, w, generator=g) < 0.05),
    }
    return {k: v.to(device) for k, v in x.items()}


def _rel(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a.float() - b.float()).abs().max() / b.float().abs().max())


@dataclass
class _Bench:
    """What the parts of :func:`run_benchmark` share: the result, the device, the repeats, the log."""

    res: BenchResult
    dev: torch.device
    repeats: int
    log: Callable[[str], None]
    #: Each part's tensors and models, held until the end, as when run_benchmark was one function:
    #: the later parts' peak memory is measured with them resident, as in the README's table.
    kept: list[object] = field(default_factory=list)

    def add(
        self, what: str, seconds: float, peak: float, speedup: float | None = None, diff: float | None = None
    ) -> None:
        """Append a row to the result and log it."""
        row = BenchRow(what=what, seconds=seconds, peak_mib=peak, speedup=speedup, max_rel_diff=diff)
        self.res.rows.append(row)
        self.log(self.res.row(row))


#: How the backends' engines are built: the one precision asked for (None: each the CPU runs well), int8's
#: calibration frames, the output fields they return (None: every map).
EngineOptions = tuple[str | None, Path | None, tuple[str, ...] | None]


def run_benchmark(
    size: tuple[int, int] = (352, 1216),
    device: str | torch.device = "cpu",
    repeats: int = 3,
    width: float = 1.0,
    parts: tuple[str, ...] = ("propagation", "backbone", "full", "fast", "backends", "train"),
    train_size: tuple[int, int] = (320, 1216),
    model: nn.Module | None = None,
    log: Callable[[str], None] = print,
    precision: str | None = None,
    calibration: Path | None = None,
    outputs: tuple[str, ...] | None = None,
    frame: dict[str, torch.Tensor] | None = None,
) -> BenchResult:
    """Measure the parts asked for; ``model`` (a full SemAttNet, or a generalist: its network) replaces random
    weights; ``frame``: the inputs (default :func:`random_frame`). ``precision``
    (``f32``, ``bf16``, ``int8``) keeps only the backends' rows of that arithmetic; ``calibration``: int8's
    calibration frames (default: synthetic scenes); ``outputs``: the fields the backends' engines return
    (``optimize_for_inference(outputs=)``; None: every map)."""
    if isinstance(model, Generalist):  # the engines run its network; the anchor is timed beside it
        return _run_generalist(model, size, device, repeats, parts, train_size, log, precision, calibration, outputs)
    if model is not None and not hasattr(model, "backbone"):
        raise InputError("model: bench needs a full SemAttNet (with refinement), not a backbone checkpoint")
    dev = torch.device(device)
    bench = _Bench(BenchResult(str(dev), torch.get_num_threads(), size), dev, repeats, log)
    fast_dtype = fast_mode_dtype(dev)
    parts = _without_unavailable_fast(parts, fast_dtype, bench.res)
    log("\n".join(bench.res.header()))
    if "propagation" in parts:
        _bench_propagation(bench, size)
    x = random_frame(size, dev) if frame is None else frame
    if any(p in parts for p in ("backbone", "full", "fast", "backends")):
        net = model if model is not None else build_model("semattnet", width=width)
        _bench_inference(bench, net.to(dev).eval(), x, parts, fast_dtype, (precision, calibration, outputs))
    if "train" in parts:
        _bench_training(bench, train_size, model, width)
    for note in bench.res.notes:
        log(note)
    return bench.res


def _without_unavailable_fast(
    parts: tuple[str, ...], fast_dtype: torch.dtype | None, res: BenchResult
) -> tuple[str, ...]:
    """``parts`` without ``fast`` (and a note why) where the fast mode would be slower than float32."""
    if "fast" not in parts or fast_dtype is not None:
        return parts
    res.notes.append(
        f"fast mode skipped: this CPU ({torch.backends.cpu.get_cpu_capability()}) has no native bfloat16 "
        "convolutions, where oneDNN's emulation is far slower than float32"
    )
    return tuple(p for p in parts if p != "fast")


def _propagation_stages(size: tuple[int, int], dev: torch.device) -> Callable[[str], torch.Tensor]:
    """Both stages of the refinement at full size, as the model runs them (heads random): ``impl`` -> depth."""
    h, w = size
    g = torch.Generator().manual_seed(0)

    def heads(hh: int, ww: int) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]:
        affs = [cspn_affinity(torch.randn(1, k * k - 1, hh, ww, generator=g)).to(dev) for k in (3, 5, 7)]
        return (
            affs,
            torch.softmax(torch.randn(1, 3, hh, ww, generator=g), 1).to(dev),
            torch.rand(1, 1, hh, ww, generator=g).to(dev),
        )

    a2, c2, m2 = heads(h // 2, w // 2)
    a1, c1, m1 = heads(h, w)
    grids = (torch.rand(1, 4, h // 2, w // 2, generator=g) * 80).to(dev)
    d = (torch.rand(1, 1, h, w, generator=g) * 80).to(dev)
    s2, s1 = grids[:, :1] * (m2 > 0.9), d * (m1 > 0.95)

    def stages(impl: str) -> torch.Tensor:
        r2 = run_cspn_stage(grids, grids, a2, c2, s2, m2, 6, impl)  # type: ignore[arg-type]
        return run_cspn_stage(d, d, a1, c1, s1, m1, 6, impl) + r2.mean()  # type: ignore[arg-type]

    return stages


def _bench_propagation(bench: _Bench, size: tuple[int, int]) -> None:
    """Rows: the refinement's propagation, the authors' pad-and-sum against ours."""
    dev = bench.dev
    stages = _propagation_stages(size, dev)
    with torch.inference_mode():
        with peak_memory(dev) as pm_naive:
            ref = stages("naive")
        with peak_memory(dev) as pm_ours:
            ours = stages("auto")
        t = interleaved({"naive": lambda: stages("naive"), "ours": lambda: stages("auto")}, dev, bench.repeats)
    bench.add("propagation, naive (authors' pad-and-sum)", t["naive"], pm_naive["peak_mib"])
    bench.add("propagation, ours", t["ours"], pm_ours["peak_mib"], t["naive"] / t["ours"], _rel(ours, ref))
    bench.kept += [stages, ref, ours]


def _bench_inference(
    bench: _Bench,
    net: nn.Module,
    x: dict[str, torch.Tensor],
    parts: tuple[str, ...],
    fast_dtype: torch.dtype | None,
    engine: EngineOptions = (None, None, None),
) -> None:
    """Rows: backbone and full model, naive against ours (and the fast mode); notes: GMACs, GFLOP/s."""
    dev = bench.dev
    gmacs = count_macs(net, x)
    peak = conv_peak_gflops(dev, bench.res.size)
    bench.res.notes.append(
        f"{gmacs:.3g} GMACs per frame (convolutions); measured conv peak {peak:.0f} GFLOP/s (float32)"
    )
    fast_net = fold_batchnorm(net)
    candidates = _inference_candidates(net, fast_net, x, parts, fast_dtype, dev, engine)
    with torch.inference_mode():
        outputs, peaks, last = _first_runs(candidates, dev)
        seconds = interleaved(candidates, dev, bench.repeats)
    for what in candidates:
        kind = what.split(",")[0]
        base = f"{kind}, naive" + (" (BN layers)" if kind == "backbone" else " reference")  # the kind's reference
        naive = what == base
        bench.add(
            what,
            seconds[what],
            peaks[what],
            None if naive else seconds[base] / seconds[what],
            None if naive else _rel(outputs[what], outputs[base]),
        )
    if "full" in parts:
        achieved = 2 * gmacs / seconds["full model, ours (float32)"]
        bench.res.notes.append(
            f"ours (float32): {achieved:.3g} GFLOP/s over the whole forward "
            f"({100 * achieved / peak:.0f} % of the measured conv peak)"
        )
    bench.kept += [net, fast_net, outputs, last]


def _inference_candidates(
    net: Any,  # SemAttNet (its propagation_impl / backbone attributes, unknown to nn.Module's type)
    fast_net: Any,
    x: dict[str, torch.Tensor],
    parts: tuple[str, ...],
    fast_dtype: torch.dtype | None,
    dev: torch.device,
    engine: EngineOptions = (None, None, None),
) -> dict[str, Callable[[], DepthCompletionOutput]]:
    """Row label -> forward pass to time; each kind's naive reference comes before ours."""

    def naive_full() -> DepthCompletionOutput:
        net.propagation_impl = "naive"
        try:
            return net(**x)
        finally:
            net.propagation_impl = "auto"

    def fast_full() -> DepthCompletionOutput:
        with torch.autocast(dev.type, dtype=fast_dtype):
            return fast_net(**x)

    candidates: dict[str, Callable[[], DepthCompletionOutput]] = {}
    if "backbone" in parts:
        candidates["backbone, naive (BN layers)"] = lambda: net.backbone(**x)
        candidates["backbone, ours (BN folded)"] = lambda: fast_net.backbone(**x)
    if any(p in parts for p in ("full", "fast", "backends")):
        candidates["full model, naive reference"] = naive_full
    if "full" in parts:
        candidates["full model, ours (float32)"] = lambda: fast_net(**x)
    if "fast" in parts:
        candidates[f"full model, fast ({str(fast_dtype).removeprefix('torch.')} autocast)"] = fast_full
    if "backends" in parts:
        candidates.update(_backend_candidates(net, x, dev, fast_dtype, *engine))
    return candidates


def _backend_candidates(
    net: nn.Module,
    x: dict[str, torch.Tensor],
    dev: torch.device,
    fast_dtype: torch.dtype | None,
    only: str | None = None,
    calibration: Path | None = None,
    outputs: tuple[str, ...] | None = None,
) -> dict[str, Callable[[], DepthCompletionOutput]]:
    """Every installed inference backend at this size that runs on ``dev`` (the engine table's), at float32;
    also bf16 where the CPU has it natively; int8 for OpenVINO with nncf installed, calibrated on synthetic
    scenes (a row, never a default); fp16 only when asked for (``only``)."""
    size = (int(x["rgb"].shape[-2]), int(x["rgb"].shape[-1]))
    wanted = {"f32"} | ({"bf16"} if fast_dtype is torch.bfloat16 else set()) | ({"fp16"} if only == "fp16" else set())
    wanted |= {"int8"} if importlib.util.find_spec("nncf") is not None else set()
    runs: dict[str, Callable[[], DepthCompletionOutput]] = {}
    for backend, entry in engine_entries().items():
        if not entry.installed() or dev.type not in entry.devices:
            continue
        for precision in [p for p in entry.precisions if p in wanted and only in (None, p)]:
            engine = optimize_for_inference(
                net,
                backend=backend,
                size=size,
                precision=precision,
                device=dev,
                calibration=calibration if precision == "int8" else None,
                outputs=outputs,
            )
            runs[f"full model, backend {backend} ({precision})"] = functools.partial(engine, **x)
    return runs


def _first_runs(
    candidates: dict[str, Callable[[], DepthCompletionOutput]], dev: torch.device
) -> tuple[dict[str, torch.Tensor], dict[str, float], DepthCompletionOutput | None]:
    """One run of each candidate (also the warm-up): its depth and its peak memory; and the last output."""
    outputs, peaks = {}, {}
    out = None
    for what, fn in candidates.items():
        with peak_memory(dev) as pm:
            out = fn()
        outputs[what] = out.depth
        peaks[what] = pm["peak_mib"]
    return outputs, peaks, out


#: (label, propagation, activation checkpointing) of the training steps measured.
_TRAIN_VARIANTS = (
    ("naive reference", "naive", False),
    ("ours", "pytorch", False),
    ("ours, activation checkpointing", "pytorch", True),
)


def _bench_training(bench: _Bench, train_size: tuple[int, int], model: nn.Module | None, width: float) -> None:
    """Rows: one training step (forward, loss, backward) per :data:`_TRAIN_VARIANTS`; notes: peak memory ratios."""
    th, tw = train_size
    xt = random_frame(train_size, bench.dev)
    gt = torch.rand(1, 1, th, tw, device=bench.dev) * 80
    base: float | None = None
    for label, impl, checkpointing in _TRAIN_VARIANTS:
        tnet = (model if model is not None else build_model("semattnet", width=width)).to(bench.dev).train()
        seconds, peak = _time_training_step(bench, tnet, impl, checkpointing, xt, gt)
        del tnet
        base = base or peak
        bench.add(f"training step {th}x{tw}, {label}", seconds, peak)
        bench.res.notes.append(f"training peak memory, {label}: {peak / base:.2f}x the naive reference's")


def _time_training_step(
    bench: _Bench, tnet: Any, impl: str, checkpointing: bool, xt: dict[str, torch.Tensor], gt: torch.Tensor
) -> tuple[float, float]:
    """Median seconds and peak MiB of a training step of ``tnet`` with that propagation and checkpointing."""
    tnet.propagation_impl = impl
    set_gradient_checkpointing(tnet, checkpointing)

    def step() -> None:
        loss = semattnet_loss(tnet(**xt), gt, 0.0)
        loss.backward()
        tnet.zero_grad(set_to_none=True)

    with peak_memory(bench.dev) as pm:
        seconds = timeit(step, bench.dev, max(1, bench.repeats - 1))
    tnet.propagation_impl = "auto"
    set_gradient_checkpointing(tnet, False)
    return seconds, pm["peak_mib"]


def _network_frame(prepared: GeneralistInputs) -> tuple[dict[str, torch.Tensor], tuple[int, int]]:
    """What a generalist's network reads (the prepared colours and depth, the fallback-free semantic colours at the
    network's resolution), padded as the completer pads it, and that size."""
    from semattnet.inference.padding import pad_to_multiple

    rgb, _ = pad_to_multiple(prepared.rgb)
    depth, _ = pad_to_multiple(prepared.depth)
    semantic = torch.full_like(rgb, 128.0) if prepared.semantic is None else pad_to_multiple(prepared.semantic)[0]
    return {"rgb": rgb, "semantic": semantic, "sparse": depth}, (int(rgb.shape[-2]), int(rgb.shape[-1]))


def _run_generalist(
    model: Generalist,
    size: tuple[int, int],
    device: str | torch.device,
    repeats: int,
    parts: tuple[str, ...],
    train_size: tuple[int, int],
    log: Callable[[str], None],
    precision: str | None,
    calibration: Path | None,
    outputs: tuple[str, ...] | None,
) -> BenchResult:
    """A generalist: its network on prepared inputs (the rows), and the non-learned steps around it (a note)."""
    x = random_frame(size, torch.device(device))
    model = model.to(device).eval()
    with torch.inference_mode():
        prepared = model.prepare(x["rgb"], x["sparse"], x["semantic"])
        seconds = []
        for _ in range(max(1, repeats)):
            t0 = time.perf_counter()
            model.prepare(x["rgb"], x["sparse"], x["semantic"])
            seconds.append(time.perf_counter() - t0)
    frame, net_size = _network_frame(prepared)
    res = run_benchmark(
        net_size,
        device,
        repeats,
        1.0,
        tuple(p for p in parts if p != "train"),
        train_size,
        model.net,
        log,
        precision,
        calibration,
        outputs,
        frame,
    )
    note = "generalist: the rows time its network"
    if prepared.size is not None:
        note += f" at {net_size[0]}x{net_size[1]} (1/{model.config.work_scale} of the frame, padded to 32)"
    note += "; its anchor (two classical completions, scale, colours) takes "
    res.notes.append(note + f"{1000 * min(seconds):.0f} ms beside it (best of {len(seconds)})")
    log(res.notes[-1])
    return res
