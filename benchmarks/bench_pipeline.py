"""The whole ``predict --stream`` pipeline against the network alone, over the same frames, in one process.

    python benchmarks/bench_pipeline.py [--frames 20] [--size 352x1216] [--width 1.0] [--prefetch 2]
                                        [--backend torch] [--precision int8] [--rounds 2] [--json out.json]

Writes a KITTI raw drive of ``--frames`` frames into a temporary folder: the bundled frame
(``tests/data/kitti_sample``: a 1242x375 image and its 120k-point Velodyne scan) copied, the image resized
to ``--size`` and the camera's calibration scaled with it (``S_rect_02``, the rows of ``P_rect_02``), so
each scan projects into the resized image as into the original. Then, with one ``DepthCompleter`` (random
weights of ``--width``, ``--backend`` as ``predict --backend``, default ``torch`` as there), in turns
(``--rounds`` times, after one untimed call that builds the engine):

* **network**: the completer called on the frames already read, projected and given their semantic map
  (the fallback map, as ``predict --kitti-raw`` without ``--semantic``): frames per second;
* **pipeline**: :func:`semattnet.inference.pipeline.complete_frames` over the drive as ``predict --kitti-raw
  DRIVE --stream --out OUT`` runs it: the same sinks (``default_sinks()``: depth and colour PNGs) plus
  ``LatencySink``, ``prefetch=--prefetch`` (``--stream`` is 2), into a fresh folder each turn. Timed: the
  loop (``complete_frames`` after ``check_frames``, as ``predict`` checks every input before it loads the
  model); the check is reported beside it.

Reported: the median frames per second of each, ``overhead = 1 - fps_pipeline / fps_network`` (the goal of
issue 36: at most 5 %), the same with the check counted, and the per-stage table of the last turn's
``latency.json``. The random weights' per-frame warnings (holes, clamped pixels) and the fallback map's are
silenced.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATE = REPO / "tests/data/kitti_sample/kitti_raw/2011_09_26"
DRIVE = "2011_09_26_drive_0035_sync"
FRAME = "0000000005"


def _scaled_calibration(text: str, sx: float, sy: float, size: tuple[int, int]) -> str:
    """``calib_cam_to_cam.txt`` with camera 02's image size and projection scaled (x by ``sx``, y by ``sy``)."""
    lines = []
    for line in text.splitlines():
        key, _, rest = line.partition(":")
        if key == "S_rect_02":
            line = f"S_rect_02: {size[1]:.6e} {size[0]:.6e}"
        elif key == "P_rect_02":
            p = np.array(rest.split(), dtype=np.float64).reshape(3, 4) * np.array([[sx], [sy], [1.0]])
            line = "P_rect_02: " + " ".join(f"{v:.6e}" for v in p.ravel())
        lines.append(line)
    return "\n".join(lines) + "\n"


def make_drive(root: Path, frames: int, size: tuple[int, int]) -> Path:
    """A raw drive of ``frames`` copies of the bundled frame at ``size`` (H, W) under ``root``; its folder."""
    from PIL import Image

    date = root / DATE.name
    drive = date / DRIVE
    for sub in ("image_02/data", "velodyne_points/data"):
        (drive / sub).mkdir(parents=True)
    shutil.copy(DATE / "calib_velo_to_cam.txt", date)
    image = Image.open(DATE / DRIVE / "image_02/data" / f"{FRAME}.png")
    sx, sy = size[1] / image.width, size[0] / image.height
    calib = (DATE / "calib_cam_to_cam.txt").read_text()
    (date / "calib_cam_to_cam.txt").write_text(_scaled_calibration(calib, sx, sy, size))
    image = image.resize((size[1], size[0]), Image.BILINEAR) if (sx, sy) != (1.0, 1.0) else image
    for i in range(frames):
        image.save(drive / "image_02/data" / f"{i:010d}.png")
        scan = f"velodyne_points/data/{i:010d}.bin"
        shutil.copy(DATE / DRIVE / "velodyne_points/data" / f"{FRAME}.bin", drive / scan)
    return drive


def _network_pass(completer: Any, frames: list[Any]) -> float:
    """Frames per second of the completer alone on frames already read."""
    t0 = time.perf_counter()
    for f in frames:
        completer(f.rgb, f.sparse, f.semantic)
    return len(frames) / (time.perf_counter() - t0)


def _pipeline_pass(completer: Any, drive: Path, out: Path, prefetch: int) -> dict[str, Any]:
    """One ``predict --kitti-raw --stream`` run: frames per second of the loop, the check's seconds, the table."""
    from semattnet.data.sources import RawDriveSource
    from semattnet.inference.pipeline import RunOptions, check_frames
    from semattnet.inference.sinks import LatencySink, default_sinks
    from semattnet.inference.timing import LATENCY_FILE, StageTimes

    timer = StageTimes()
    source = RawDriveSource(drive)
    sinks = [*default_sinks(), LatencySink(timer=timer)]
    t0 = time.perf_counter()
    plan = check_frames(source, sinks, out, options=RunOptions(prefetch=prefetch))
    t1 = time.perf_counter()
    plan.run(completer, timer=timer, log=lambda _: None)
    t2 = time.perf_counter()
    n = len(source.names)
    return {
        "fps": n / (t2 - t1),
        "check_s": t1 - t0,
        "fps_with_check": n / (t2 - t0),
        "latency": json.loads((out / LATENCY_FILE).read_text()),
        "table": timer.table(),
    }


def measure(
    drive: Path, work: Path, width: float, backend: str, prefetch: int, rounds: int, precision: str | None = None
) -> dict[str, Any]:
    """The network alone and the pipeline over the drive's frames, in turns; medians and the overhead."""
    import torch

    import semattnet
    from semattnet.data.sources import RawDriveSource
    from semattnet.inference import DepthCompleter
    from semattnet.inference.backends import EngineSpec
    from semattnet.inference.feed import read_frame
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.timing import StageTimes

    torch.manual_seed(0)
    completer = DepthCompleter(
        semattnet.build_model("semattnet", width=width),
        EngineSpec(backend=backend, precision=precision, device="cpu"),
        inplace=True,
    )
    source = RawDriveSource(drive)
    maps = SemanticMaps().bind(completer)
    frames = [read_frame(source, name, maps, StageTimes()) for name in source.names]
    completer(frames[0].rgb, frames[0].sparse, frames[0].semantic)  # builds the engine (untimed)
    net, pipe = [], []
    for i in range(rounds):
        net.append(_network_pass(completer, frames))
        pipe.append(_pipeline_pass(completer, drive, work / f"out{i}", prefetch))
    fps_net, fps_pipe = statistics.median(net), statistics.median(p["fps"] for p in pipe)
    fps_check = statistics.median(p["fps_with_check"] for p in pipe)
    last = pipe[-1]
    return {
        "frames": len(frames),
        "fps_network": fps_net,
        "fps_pipeline": fps_pipe,
        "overhead": 1 - fps_pipe / fps_net,
        "overhead_with_check": 1 - fps_check / fps_net,
        "check_s": statistics.median(p["check_s"] for p in pipe),
        "rounds_fps_network": net,
        "rounds_fps_pipeline": [p["fps"] for p in pipe],
        "stages": last["latency"]["stages"],
        "latency": last["latency"],
        "table": last["table"],
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=20)
    p.add_argument("--size", default="352x1216", help="HxW of the drive's images")
    p.add_argument("--width", type=float, default=1.0)
    p.add_argument("--prefetch", type=int, default=2, help="frames read ahead (predict --stream: 2)")
    p.add_argument("--backend", default="torch", help="as predict --backend (default torch)")
    p.add_argument("--precision", default=None, help="as predict --precision (e.g. int8 with openvino)")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    h, w = (int(v) for v in args.size.lower().split("x"))
    from semattnet._utils.cpu import cpu_summary

    print(f"load before: {os.getloadavg()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="semattnet-bench-pipeline-") as tmp:
        drive = make_drive(Path(tmp) / "raw", args.frames, (h, w))
        with warnings.catch_warnings():  # random weights: each frame's holes and clamps; the fallback semantic map
            warnings.simplefilter("ignore", UserWarning)
            r = measure(drive, Path(tmp), args.width, args.backend, args.prefetch, args.rounds, args.precision)
    r |= {
        "cpu": cpu_summary(),
        "size": [h, w],
        "width": args.width,
        "backend": args.backend,
        "precision": args.precision or "f32",
        "prefetch": args.prefetch,
        "load_after": os.getloadavg(),
    }
    print(
        f"CPU: {r['cpu']}; {r['frames']} frames at {h}x{w}, width {args.width}, backend {args.backend} "
        f"({r['precision']}), prefetch {args.prefetch}"
    )
    print(
        f"network alone {r['fps_network']:.3f} frames/s, pipeline {r['fps_pipeline']:.3f} frames/s: overhead "
        f"{100 * r['overhead']:.1f} % ({100 * r['overhead_with_check']:.1f} % with the input check, "
        f"{r['check_s']:.2f} s)"
    )
    print(r.pop("table"))
    if args.json:
        args.json.write_text(json.dumps(r, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
