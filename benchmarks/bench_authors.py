"""Inference against the authors' own code: the same weights, float32, batch 1, timed in turns in one process.

    python benchmarks/bench_authors.py --authors-src DIR [--size 352x1216] [--rounds 3]
                                       [--engines torch,openvino[,int8]] [--no-int8] [--no-memory] [--json out.json]

``DIR`` is a clone of https://github.com/danishnazir/SemAttNet; its ``model.py`` is imported from there at run
time (``authors_code.py`` beside this script says how, and what is shimmed). Their ``A_CSPN_plus_plus`` is
filled with deterministic weights (``authors_code.fill_weights``), and its state dict is loaded (strict)
into our ``semattnet.build_model("semattnet")``: the same network, the same weights.

**Speed** (this process): their model (``eval()``, ``torch.inference_mode()``) and ours through
``optimize_for_inference(model, backend=ENGINE, size=SIZE)`` for each of ``--engines`` (``torch``: BatchNorm
folded, the fused propagation; ``openvino``: what ``backend="auto"`` picks on a CPU where it is installed, the
default of ``semattnet bench``'s backend rows); each is run once untimed (the warm-up, and the outputs compared:
``max |ours - theirs| / max |theirs|`` of ``refined_depth``), then ``--rounds`` turns ``theirs, ours...``; the
median seconds per frame and the speed-up ``theirs / ours``.

**Peak memory** (first, one child process per variant, as ``bench_training.py`` does): only that model is
built (ours filled by the same rule, so the weights are equal) and its engine made; what was freed is handed
back to the system (``gc``, glibc's ``malloc_trim``), the resident set's high-water mark reset
(``/proc/self/clear_refs``) and two inferences run: ``inference_peak_mib`` is the peak over those;
``process_peak_mib`` the child's whole-life peak (``VmHWM`` before the reset: the build, the export, the
calibration; not ``ru_maxrss``, which Linux carries over from the parent through ``exec``). The variants:
theirs, ours per engine and ``int8`` (OpenVINO + NNCF, ``precision="int8"``, default calibration; not with
``--no-int8`` or without ``nncf``).

``--width`` is for stand-ins in tests: their released model has one width, 1.0.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import importlib.util
import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from authors_code import build_authors_model, fill_weights

ENGINES = ("torch", "openvino")
#: ``--engines`` may also name ``int8`` (OpenVINO + NNCF, default calibration): its speed in the same turns.
OPTIONAL_ENGINES = ("int8",)
THEIRS = "authors"


def parse_size(text: str) -> tuple[int, int]:
    h, w = (int(v) for v in text.lower().split("x"))
    return h, w


def _ours(width: float) -> torch.nn.Module:
    import semattnet

    return semattnet.build_model("semattnet", width=width).eval()


def _engine(net: torch.nn.Module, engine: str, size: tuple[int, int], inplace: bool = False) -> Callable[..., Any]:
    """Ours ready to run: ``engine`` is ``torch``, ``openvino`` or ``int8`` (OpenVINO + NNCF)."""
    from semattnet.inference.backends import optimize_for_inference

    backend, precision = ("openvino", "int8") if engine == "int8" else (engine, "f32")
    return optimize_for_inference(net, backend=backend, size=size, precision=precision, inplace=inplace)


def measure_speed(
    src: Path, size: tuple[int, int], engines: tuple[str, ...], rounds: int, width: float
) -> dict[str, Any]:
    """Median seconds per frame of theirs and of ours per engine, in turns; speed-ups and parity errors."""
    from semattnet.apps.benchmark import random_frame
    from semattnet.apps.timing import interleaved

    cpu = torch.device("cpu")
    theirs = build_authors_model(src, size).eval()
    ours = _ours(width)
    ours.load_state_dict(theirs.net.state_dict(), strict=True)
    x = random_frame(size, cpu)
    runs: dict[str, Callable[[], Any]] = {THEIRS: lambda: theirs(**x)}
    for e in engines:
        engine = _engine(ours, e, size)
        runs[f"ours-{e}"] = lambda f=engine: f(**x)
    with torch.inference_mode():
        depth = {k: f().refined_depth for k, f in runs.items()}  # the warm-up, and the outputs compared
        seconds = interleaved(runs, cpu, rounds)
    ref = depth[THEIRS]
    err = {k: float((d - ref).abs().max() / ref.abs().max()) for k, d in depth.items() if k != THEIRS}
    speedup = {k: seconds[THEIRS] / s for k, s in seconds.items() if k != THEIRS}
    return {"seconds": seconds, "speedup": speedup, "max_rel_error": err}


def memory_child(variant: str, src: Path, size: tuple[int, int], width: float) -> dict[str, float | str]:
    """Peak memory of one variant's inference in this (fresh) process."""
    from semattnet.apps.benchmark import random_frame
    from semattnet.apps.timing import peak_memory

    cpu = torch.device("cpu")
    if variant == THEIRS:
        model: Callable[..., Any] = build_authors_model(src, size).eval()
    else:
        net = fill_weights(_ours(width))
        model = _engine(net, variant.removeprefix("ours-"), size, inplace=True)
        del net
    x = random_frame(size, cpu)
    build = _release_freed()
    with torch.inference_mode(), peak_memory(cpu) as pm:
        for _ in range(2):
            model(**x)
    return {"variant": variant, "inference_peak_mib": pm["peak_mib"], "process_peak_mib": max(build, pm["peak_mib"])}


def _release_freed() -> float:
    """Free what is unreachable and hand glibc's free pages back to the system; the peak so far (MiB, ``VmHWM``)."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: the freed pages may stay counted
        pass
    from semattnet.apps.timing import status_mib

    return status_mib("VmHWM")


def _run_child(args: argparse.Namespace, variant: str) -> dict[str, Any] | None:
    cmd = [
        sys.executable,
        __file__,
        "--child",
        variant,
        "--authors-src",
        str(args.authors_src),
        "--size",
        args.size,
        "--width",
        str(args.width),
    ]
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=False)
    if proc.returncode != 0:
        print(f"  memory of {variant}: failed (exit {proc.returncode})", flush=True)
        return None
    return json.loads(proc.stdout.strip().splitlines()[-1])


def measure_memory(args: argparse.Namespace, engines: tuple[str, ...]) -> dict[str, Any]:
    """Each variant's peak memory in its own process, and ours against theirs."""
    variants = [THEIRS, *(f"ours-{e}" for e in engines)]
    if args.int8 and "int8" not in engines and importlib.util.find_spec("nncf") is not None:
        variants.append("ours-int8")
    peaks = {v: r for v in variants if (r := _run_child(args, v)) is not None}
    base = peaks.get(THEIRS, {}).get("inference_peak_mib")
    ratio = {v: r["inference_peak_mib"] / base for v, r in peaks.items() if base and v != THEIRS}
    return {"peaks": peaks, "ratio": ratio}


def table(r: dict[str, Any]) -> list[str]:
    """The result as lines: per variant, seconds, speed-up, parity error, peak memory and its ratio."""
    speed, memory = r.get("speed", {}), r.get("memory", {})
    names = list(dict.fromkeys([*speed.get("seconds", {}), *memory.get("peaks", {})]))
    head = " ".join(
        f"{h:>{n}s}" for h, n in (("s/frame", 8), ("x theirs", 8), ("rel err", 8), ("peak MiB", 9), ("x theirs", 8))
    )
    timed_int8 = "ours-int8" in speed.get("seconds", {})
    what = "float32 and int8" if timed_int8 else "float32 (int8: memory only)"
    lines = [
        f"CPU: {r['cpu']}; {r['size'][0]}x{r['size'][1]}, batch 1, {what}, {r['threads']} threads",
        f"{'variant':14s} {head}",
    ]
    for v in names:
        sec = speed.get("seconds", {}).get(v)
        up, err = speed.get("speedup", {}).get(v), speed.get("max_rel_error", {}).get(v)
        peak, ratio = memory.get("peaks", {}).get(v, {}).get("inference_peak_mib"), memory.get("ratio", {}).get(v)
        cells = [_cell(sec, "8.3f"), _cell(up, "8.2f"), _cell(err, "8.1e"), _cell(peak, "9.0f"), _cell(ratio, "8.2f")]
        lines.append(f"{v:14s} " + " ".join(cells))
    return lines


def _cell(value: float | None, fmt: str) -> str:
    width = int(fmt.split(".")[0])
    return format(value, fmt) if value is not None else " " * width


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--authors-src", type=Path, required=True, help="a clone of danishnazir/SemAttNet")
    p.add_argument("--size", default="352x1216")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--engines", default=",".join(ENGINES), help="ours: comma-separated, of torch, openvino, int8")
    p.add_argument("--width", type=float, default=1.0, help="ours' width (their released model: 1.0)")
    p.add_argument("--no-int8", dest="int8", action="store_false", help="leave int8 out of the memory table")
    p.add_argument("--no-memory", dest="memory", action="store_false", help="time only (no child processes)")
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    size, engines = parse_size(args.size), tuple(e for e in args.engines.split(",") if e)
    if not set(engines) <= {*ENGINES, *OPTIONAL_ENGINES}:
        p.error(f"--engines: expected some of {', '.join((*ENGINES, *OPTIONAL_ENGINES))}, got {args.engines!r}")
    if args.child:
        print(json.dumps(memory_child(args.child, args.authors_src, size, args.width)))
        return 0
    from semattnet._utils.cpu import cpu_summary

    r: dict[str, Any] = {
        "cpu": cpu_summary(),
        "size": list(size),
        "threads": torch.get_num_threads(),
        "rounds": args.rounds,
        "load_before": os.getloadavg(),
    }
    print(f"load before: {r['load_before']}", flush=True)
    if args.memory:  # first, while this process holds no model (the children start beside it)
        r["memory"] = measure_memory(args, engines)
    r["speed"] = measure_speed(args.authors_src, size, engines, args.rounds, args.width)
    r["load_after"] = os.getloadavg()
    print("\n".join(table(r)))
    if args.json:
        args.json.write_text(json.dumps(r, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
