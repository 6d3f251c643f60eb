"""Remake the figure at the top of the README and the docs home: ``make figures`` (this script, ``--out docs``).

It draws the trained weights shipped in the package and the classical completion on the demo's held-out
scenes (see ``semattnet.apps.front_figure``); about 10 minutes on 2 CPU cores. The scenes and the sweep's
tables are made in a temporary folder (``--work`` keeps them).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from semattnet.apps.front_figure import make_front_figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs"), help="folder of sparsity-sweep.png/.json [docs]")
    parser.add_argument("--work", type=Path, default=None, help="keep the scenes and tables here [a temporary folder]")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    if args.work is not None:
        numbers = make_front_figure(args.out, args.work, device=args.device)
    else:
        with tempfile.TemporaryDirectory(prefix="semattnet-figures-") as tmp:
            numbers = make_front_figure(args.out, Path(tmp), device=args.device)
    for name, summary in numbers["uncertainty"].items():
        print(f"{name}: " + ", ".join(f"{k} {v:.3f}" for k, v in summary.items()))
    print(f"wrote {args.out / 'sparsity-sweep.png'} and {args.out / 'sparsity-sweep.json'}")


if __name__ == "__main__":
    main()
