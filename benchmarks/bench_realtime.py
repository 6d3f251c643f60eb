"""``predict --bag --realtime`` end to end on a 10 Hz recording: frames fed, completed and dropped, and where the
time goes per stage.

Writes an MCAP bag (the repository's bag writer, :func:`semattnet.robotics.bags.write_sensor_bag`) of ``--frames``
frames at ``--size`` (default 352x1216), 10 Hz, cycling over ``--scenes`` synthetic street scenes
(:func:`semattnet.data.synthetic.scenes.make_frame`: an image and its simulated LiDAR scan), then runs
``semattnet predict --bag BAG --realtime`` on it in this process (the command's own code: depth and colour PNGs
written, ``latency.json``), with ``--weights W``, ``--model NAME`` (that registered model with random weights:
times do not depend on the weights) or the classical completion (the default). Prints the latency table
and one JSON line (``--json`` also writes it): frames fed, completed, dropped and skipped, the exit status,
``latency.json`` (median and p95 per stage, which stages run beside the network, the serial path), the CPU::

    python benchmarks/bench_realtime.py --frames 100 --model semattnet_rt_s --out /tmp/rt --json rt.json
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
    from semattnet.data.synthetic.scenes import make_frame
    from semattnet.geometry.calibration import RigCalibration
    from semattnet.robotics.bags import SensorRecord, write_sensor_bag

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


def run_predict(bag: Path, out: Path, method: Sequence[str], speed: float) -> int:
    """``semattnet predict --bag BAG --realtime`` in this process; its exit status (4: frames were dropped)."""
    from semattnet.cli import main
    from semattnet.robotics.bags import BagTopics

    topics = BagTopics()
    args = ["predict", "--bag", str(bag), "--image-topic", topics.image, "--points-topic", topics.points,
            *method, "--out", str(out), "--realtime", "--speed", f"{speed:g}", "--overwrite"]  # fmt: skip
    code = main.main(args, prog_name="semattnet", standalone_mode=False)
    return int(code or 0)


def report(out: Path, fed: int, code: int, size: tuple[int, int], method: Sequence[str]) -> dict[str, Any]:
    """What the run did, from its ``frames.json`` and ``latency.json``."""
    frames = json.loads((out / "frames.json").read_text())["frames"]
    status = [f["status"] for f in frames]
    latency = json.loads((out / "latency.json").read_text())
    return {"frames_fed": fed, "completed": status.count("done"), "dropped": status.count("dropped"),
            "skipped": status.count("skipped"), "exit_code": code, "size": list(size), "method": " ".join(method),
            "latency": latency, "cpu": cpu_name()}  # fmt: skip


def _args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--size", default="352x1216", help="HxW of the recording")
    parser.add_argument("--scenes", type=int, default=4, help="distinct synthetic scenes, cycled")
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--weights", help="weights to complete with (a name, file or folder)")
    how.add_argument("--model", help="a registered model, with random weights (e.g. semattnet_rt_s)")
    parser.add_argument("--speed", type=float, default=1.0, help="replay this many times faster than recorded")
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
    method = ["--method", "classical"]
    if args.weights or args.model:
        method = ["--weights", args.weights or str(random_weights(args.model, args.out / "weights"))]
    code = run_predict(bag, args.out / "pred", method, args.speed)
    r = report(args.out / "pred", args.frames, code, (h, w), method)
    print(f"CPU: {r['cpu']}; {r['frames_fed']} frames fed at 10 Hz x {args.speed:g}: {r['completed']} completed, "
          f"{r['dropped']} dropped, {r['skipped']} skipped")  # fmt: skip
    print(json.dumps(r))
    if args.json is not None:
        args.json.write_text(json.dumps(r, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
