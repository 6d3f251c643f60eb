"""The live node's per-frame output work: building and serialising its messages at 375x1242, by cloud stride.

For a KITTI-sized frame (375x1242, a smooth completed depth with a few holes, an uncertainty), times
:class:`~semattnet.robotics.frame.RobotFrame` built as the node builds it (the float depth, the cloud of every
N-th pixel from the cached rays; ``--publish`` all four outputs) and its messages serialised to CDR as the DDS
transport sends them, for each ``--strides`` value; and, for comparison, the whole-image cloud the recordings
use (:func:`~semattnet.geometry.depth_to_points`, stride "full"). Prints the median and p95 per stage, the
points and bytes, the ratios to stride 1 and the CPU::

    python benchmarks/bench_node_outputs.py --frames 30 --strides 1 2 4 8
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

H, W = 375, 1242
K = np.array([[721.5377, 0.0, 609.5593], [0.0, 721.5377, 172.854], [0.0, 0.0, 1.0]])


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else the platform's."""
    info = Path("/proc/cpuinfo")
    if info.exists():
        for line in info.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def prediction() -> object:
    """One completed frame as the node's sinks see it (``predict_frame``), KITTI-sized."""
    import warnings

    from semattnet.data.frames import Frame, SensorMeta
    from semattnet.inference.contract import Completion
    from semattnet.inference.sinks import predict_frame
    from semattnet.robotics.frame import pinhole_info

    rng = np.random.default_rng(0)
    v, u = np.mgrid[0:H, 0:W]
    depth = (5 + 60 * (v / H) ** 2 + 2 * np.sin(u / 50)).astype(np.float32)
    depth[rng.random((H, W)) < 0.01] = 0
    rgb = rng.integers(0, 255, (H, W, 3), np.uint8)
    meta = SensorMeta(stamp_ns=1, frame_id="cam", lidar_frame_id="velo", camera_info=pinhole_info(K, W, H))
    frame = Frame("f", rgb, np.zeros((H, W), np.float32), K=K, meta=meta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return predict_frame(frame, Completion(depth, uncertainty=0.05 * depth))


def time_stride(pred: object, stride: int | None, frames: int) -> dict[str, object]:
    """Median / p95 ms of building the frame (cloud included) and serialising its messages; stride None: the
    whole-image cloud of depth_to_points."""
    from semattnet.robotics.bags.deps import rosbags_typestore
    from semattnet.robotics.frame import ROS_TYPES, RobotFrame

    ts = rosbags_typestore(False)
    build, serial, points, size = [], [], 0, 0
    for _ in range(frames + 1):  # the first builds the rays (cached): not timed
        t0 = time.perf_counter()
        robot = RobotFrame.of(pred, uncertainty=True, float_depth=True, cloud_stride=stride)  # type: ignore[arg-type]
        msgs = robot.messages(ts)
        t1 = time.perf_counter()
        wire = [ts.serialize_cdr(m, ROS_TYPES[role]) for role, m in msgs.items()]
        t2 = time.perf_counter()
        build.append(t1 - t0)
        serial.append(t2 - t1)
        points, size = len(robot.cloud), sum(len(b) for b in wire)
    b, s = np.array(build[1:]) * 1e3, np.array(serial[1:]) * 1e3
    return {
        "build": (float(np.median(b)), float(np.percentile(b, 95))),
        "serialise": (float(np.median(s)), float(np.percentile(s, 95))),
        "points": points,
        "bytes": size,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--strides", type=int, nargs="+", default=[1, 2, 4, 8])
    args = parser.parse_args()
    pred = prediction()
    print(f"CPU: {cpu_name()}; {H}x{W}, {args.frames} frames per row; ms median / p95")
    rows = {str(s): time_stride(pred, s, args.frames) for s in args.strides}
    rows["full (depth_to_points)"] = time_stride(pred, None, args.frames)
    base = rows.get("1")
    for name, r in rows.items():
        (bm, bp), (sm, sp) = r["build"], r["serialise"]  # type: ignore[misc]
        total = bm + sm
        ratio = "" if base is None else f", {total / (base['build'][0] + base['serialise'][0]):.2f}x stride 1"  # type: ignore[index]
        print(
            f"stride {name}: build {bm:.1f}/{bp:.1f}, serialise {sm:.1f}/{sp:.1f} ms; "
            f"{r['points']} points, {int(r['bytes']) / 1e6:.2f} MB{ratio}"  # type: ignore[call-overload]
        )


if __name__ == "__main__":
    main()
