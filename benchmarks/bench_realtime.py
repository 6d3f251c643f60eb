"""``predict --bag --realtime`` end to end on a 10 Hz recording: frames fed, completed and dropped, and where the
time goes per stage.

Writes an MCAP bag (the repository's bag writer, :func:`semattnet.robotics.bags.write_sensor_bag`) of ``--frames``
frames at ``--size`` (default 352x1216), 10 Hz, cycling over ``--scenes`` synthetic street scenes
(:func:`semattnet.synthetic.scenes.make_frame`: an image and its simulated LiDAR scan), then replays it as
``semattnet predict --bag BAG --realtime`` does, through the library (the bag as frames, depth and colour PNGs and
``latency.json`` written), with ``--weights W``, ``--model NAME`` (that registered model with random weights:
times do not depend on the weights) or the classical completion (the default), after ``--warmup`` completions of
the first frame. ``--serial`` runs it a second time with the writing in line, for the difference the pipelined
frame path makes. Prints the latency tables and one JSON line (``--json`` also writes it): per run, frames fed,
completed, dropped and skipped, the exit status and ``latency.json`` (median and p95 per stage, which stages run
beside the network, the serial path); the CPU::

    python benchmarks/bench_realtime.py --frames 100 --model semattnet_rt_s --serial --out /tmp/rt --json rt.json
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from bench_rt import cpu_name

#: The sensor's period in the recording, ns (a 10 Hz LiDAR); each scan is stamped 3 ms after its image.
PERIOD_NS = 10**8
T0_NS = 1_700_000_000 * 10**9


def write_recording(path: Path, frames: int, size: tuple[int, int], scenes: int = 4) -> Path:
    """An MCAP bag of ``frames`` frames of ``size`` (H, W) at 10 Hz, cycling over ``scenes`` synthetic scenes."""
    from semattnet.geometry.calibration import RigCalibration
    from semattnet.robotics.bags import SensorRecord, write_sensor_bag
    from semattnet.synthetic.scenes import make_frame

    made = [make_frame(*size, seed=s) for s in range(max(1, min(scenes, frames)))]
    first = made[0]
    assert first.lidar_points is not None and first.T_cam_lidar is not None
    calib = RigCalibration(first.K, first.T_cam_lidar, (size[1], size[0]))

    def records() -> Iterator[SensorRecord]:
        for i in range(frames):
            scene = made[i % len(made)]
            assert scene.lidar_points is not None
            t = T0_NS + i * PERIOD_NS
            yield SensorRecord(scene.rgb, scene.lidar_points, t, t + 3 * 10**6)

    return write_sensor_bag(path, records(), calib, fmt="mcap", overwrite=True).path


def random_weights(model: str, folder: Path) -> Path:
    """The registered ``model`` with random weights, saved as a weights folder (``--weights`` takes it)."""
    import torch

    from semattnet.models.registry import build_model
    from semattnet.weights.hub import save_pretrained

    torch.manual_seed(0)
    return save_pretrained(build_model(model).eval(), folder)


def completer_of(weights: str | None, backend: str = "torch", precision: str | None = None) -> Any:
    """What ``predict --backend B --precision P`` completes with: the model of ``weights`` on that engine
    (:func:`~semattnet.inference.completer.load_completer`), else the classical completion."""
    from semattnet.baselines import ClassicalCompleter
    from semattnet.inference.backends.spec import EngineSpec
    from semattnet.inference.completer import load_completer

    if weights is None:
        return ClassicalCompleter()
    return load_completer(weights, EngineSpec(backend=backend, precision=precision, device="cpu"), progress=False)


def warm_up(completer: Any, bag: Path, calls: int) -> None:
    """``calls`` completions of the recording's first frame (one-off work: a kernel's build, the first
    allocations), as a robot's node does before its sensor starts."""
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.robotics import BagSource
    from semattnet.robotics.bags import BagTopics

    topics = BagTopics()
    source = BagSource(bag, topics.image, topics.points)
    frame = SemanticMaps().bind(completer).fill(source.load(source.names[0]))
    for _ in range(calls):
        completer(frame.rgb, frame.sparse, frame.semantic)


def run_sinks(timer: Any) -> list[Any]:
    """What ``predict --bag BAG --realtime --out OUT`` writes: the depth and colour PNGs, ``latency.json``."""
    from semattnet.inference.sinks import LatencySink, default_sinks

    return [*default_sinks(), LatencySink(timer=timer)]


def run_realtime(bag: Path, out: Path, completer: Any, speed: float, write_ahead: int | None) -> dict[str, Any]:
    """``predict --bag BAG --realtime --out OUT`` as the library runs it (the bag as frames, the depth and colour
    PNGs and ``latency.json``); ``write_ahead``: :class:`~semattnet.inference.options.RunOptions`' (None: the
    default, the writing beside the network; 0: in line). What it did: counts and ``latency.json``."""
    from semattnet.inference.pipeline import OutputSpec, RunOptions, check_frames
    from semattnet.inference.timing import StageTimes
    from semattnet.robotics import BagSource
    from semattnet.robotics.bags import BagTopics

    topics, timer = BagTopics(), StageTimes()
    source = BagSource(bag, topics.image, topics.points)
    sinks = run_sinks(timer)
    options = RunOptions(realtime=speed, write_ahead=write_ahead)
    run = check_frames(source, sinks, out, OutputSpec(overwrite=True), options).run(
        completer, timer=timer, log=lambda line: None
    )
    print(timer.table())
    counts = run.counts
    return {
        "frames_fed": len(source.names),
        "completed": counts["done"],
        "dropped": counts["dropped"],
        "skipped": counts["skipped"],
        "exit_code": run.exit_code,
        "latency": json.loads((out / "latency.json").read_text()),
    }


def _args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--size", default="352x1216", help="HxW of the recording")
    parser.add_argument("--scenes", type=int, default=4, help="distinct synthetic scenes, cycled")
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--weights", help="weights to complete with (a name, file or folder)")
    how.add_argument("--model", help="a registered model, with random weights (e.g. semattnet_rt_s)")
    parser.add_argument("--backend", default="torch", help="the engine, as predict --backend (e.g. openvino)")
    parser.add_argument("--precision", default=None, help="as predict --precision (f32, int8, ...)")
    parser.add_argument("--speed", type=float, default=1.0, help="replay this many times faster than recorded")
    parser.add_argument("--warmup", type=int, default=3, help="completions of the first frame before the replay")
    parser.add_argument("--serial", action="store_true", help="also run with the writing in line (write_ahead=0)")
    parser.add_argument("--out", type=Path, default=Path("rt-bench"), help="working folder (replaced)")
    parser.add_argument("--json", type=Path, default=None, help="also write the report here")
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = _args(argv)
    h, w = (int(v) for v in args.size.lower().split("x"))
    shutil.rmtree(args.out, ignore_errors=True)
    t = time.perf_counter()
    bag = write_recording(args.out / "recording.mcap", args.frames, (h, w), args.scenes)
    print(f"{args.frames} frames of {w}x{h} at 10 Hz written in {time.perf_counter() - t:.1f} s: {bag}")
    weights = str(random_weights(args.model, args.out / "weights")) if args.model else args.weights
    completer = completer_of(weights, args.backend, args.precision)
    if hasattr(completer, "outputs"):  # the engine the run asks for (what its sinks read) is the one warmed up
        from semattnet.inference.sinks import outputs_read

        completer.outputs = outputs_read(run_sinks(None))
    warm_up(completer, bag, args.warmup)
    runs = {}
    for name, write_ahead in [("pipelined", None), *([("serial", 0)] if args.serial else [])]:
        print(f"{name}:")
        r = runs[name] = run_realtime(bag, args.out / name, completer, args.speed, write_ahead)
        print(
            f"{r['frames_fed']} frames fed at 10 Hz x {args.speed:g}: {r['completed']} completed, "
            f"{r['dropped']} dropped, {r['skipped']} skipped"
        )
    doc = {
        "size": [h, w],
        "speed": args.speed,
        "method": args.model or weights or "classical",
        "backend": args.backend,
        "random_weights": bool(args.model),
        "warmup": args.warmup,
        "cpu": cpu_name(),
        **runs,
    }
    print(json.dumps(doc))
    if args.json is not None:
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
