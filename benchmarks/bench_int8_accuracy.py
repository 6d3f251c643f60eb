"""int8 (and bf16) against float32 on a trained checkpoint: the four KITTI metrics, the largest
pixel difference and the time per frame. The same script as ``bench_fast_mode_accuracy.py``:

    python benchmarks/bench_int8_accuracy.py CHECKPOINT SYNTH_TREE [--calibration-frames 32]
"""

from __future__ import annotations

import runpy
from pathlib import Path

if __name__ == "__main__":
    runpy.run_path(str(Path(__file__).with_name("bench_fast_mode_accuracy.py")), run_name="__main__")
