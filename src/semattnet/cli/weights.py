"""``semattnet weights list`` / ``weights fetch``: the released-weights registry and the download cache."""

from __future__ import annotations

from collections.abc import Mapping

import click

from semattnet.cli._group import main

_UNKNOWN_SHA = "unknown (pinned on first download)"


@main.group()
def weights() -> None:
    """Released weights: list the registry, download into the verified cache."""


@weights.command("list")
def weights_list() -> None:
    """Table of released weights: architecture, size, training data, file, checksum, licence and reported RMSE."""
    click.echo(weights_table())


@weights.command("fetch")
@click.argument("name", metavar="NAME|URL")
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def weights_fetch(name: str, progress: bool) -> None:
    """Download NAME (a registry name or URL) into the cache; print its path and sha256."""
    from semattnet.cache import DownloadError, sha256_file
    from semattnet.cli._options import resolve_option

    try:
        path = resolve_option(name, "NAME", progress=progress).file
    except DownloadError as exc:
        raise click.ClickException(f"{exc} (run the same command again to resume)") from None
    click.echo(f"path:   {path}")
    click.echo(f"sha256: {sha256_file(path)}")


def weights_table() -> str:
    """``semattnet weights list``: name, architecture, parameters, training data, file, sha256 (or pin),
    licence, reported RMSE (the paper's for the authors' weights, the own validation scenes' for the demo's)."""
    header = ("name", "arch", "params", "trained on", "file", "sha256", "licence", "reported RMSE")
    rows = _weights_rows()
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = ["  ".join(c.ljust(wd) for c, wd in zip(r, widths, strict=True)).rstrip() for r in [header, *rows]]
    return "\n".join([lines[0], "  ".join("-" * wd for wd in widths), *lines[1:]])


def _licence(text: str) -> str:
    """The licence's first clause (the registry holds a paragraph)."""
    head = text.split(":", 1)[0].split(";", 1)[0].strip()
    return head if len(head) <= 40 else head[:39] + "…"


def _rmse(metrics: Mapping[str, Mapping[str, float]]) -> str:
    parts = [f"{split} {m['rmse_mm']:g} mm" for split, m in metrics.items() if "rmse_mm" in m]
    return ", ".join(parts) or "-"


def _weights_rows() -> list[tuple[str, ...]]:
    from semattnet.cache import read_pins
    from semattnet.weights.pretrained import get_weights, list_pretrained

    pins = read_pins()
    rows: list[tuple[str, ...]] = []
    for name in list_pretrained():
        w = get_weights(name)
        pinned = pins.get(f"{w.name}/{w.file_name}", {}).get("sha256")
        sha = w.sha256 or (f"{pinned} (pinned)" if pinned else _UNKNOWN_SHA)
        params = f"{w.num_params / 1e6:.1f} M" if w.num_params else "?"
        rows.append(
            (w.name, w.arch, params, w.trained_on or "-", w.file_name, sha, _licence(w.license), _rmse(w.paper_metrics))
        )
    return rows
