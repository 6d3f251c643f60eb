"""Latency, throughput and peak memory of SemAttNet against the naive reference (the authors'
pad-and-sum propagation and un-folded BatchNorm), in one process; the same as `semattnet bench`.

    python benchmarks/bench_inference.py [--size 352x1216] [--repeats 3] [--parts propagation,full,fast]
                                         [--json results.json] [--checkpoint trained.pt]
"""

from __future__ import annotations

import sys

from semattnet.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
