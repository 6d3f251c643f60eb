"""Option parsing shared by the commands: sizes, triples, comma lists."""

from __future__ import annotations

import click


def parse_size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected HxW, e.g. 96x320; got {text!r}") from None
    return h, w


def parse_triple(text: str, option: str) -> tuple[float, float, float]:
    try:
        a, b, c = (float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(f"expected three numbers R,G,B; got {text!r}", param_hint=option) from None
    return a, b, c
