"""``semattnet weights list`` / ``weights fetch``: the released-weights registry and the download cache."""

from __future__ import annotations

from pathlib import Path

import click

from semattnet.cli._group import main

_UNKNOWN_SHA = "unknown (pinned on first download)"


def _licence(text: str) -> str:
    """The licence's first clause (the registry holds a paragraph)."""
    head = text.split(":", 1)[0].split(";", 1)[0].strip()
    return head if len(head) <= 40 else head[:39] + "…"


def _rmse(metrics: dict) -> str:
    parts = [f"{split} {m['rmse_mm']:g} mm" for split, m in metrics.items() if "rmse_mm" in m]
    return ", ".join(parts) or "-"


def _rows() -> list[tuple[str, ...]]:
    from semattnet.weights import get_weights, list_pretrained, read_pins

    pins = read_pins()
    rows = []
    for name in list_pretrained():
        w = get_weights(name)
        pinned = pins.get(f"{w.name}/{w.file_name}", {}).get("sha256")
        sha = w.sha256 or (f"{pinned} (pinned)" if pinned else _UNKNOWN_SHA)
        params = f"{w.num_params / 1e6:.1f} M" if w.num_params else "?"
        rows.append((w.name, w.arch, params, w.file_name, sha, _licence(w.license), _rmse(dict(w.paper_metrics))))
    return rows


def _table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = ["  ".join(c.ljust(wd) for c, wd in zip(r, widths, strict=True)).rstrip() for r in [header, *rows]]
    return "\n".join([lines[0], "  ".join("-" * wd for wd in widths), *lines[1:]])


def weights_file(spec: str, progress: bool = True) -> Path:
    """A local weights file for ``--weights NAME|PATH|URL``: registry names and URLs go through the cache.

    A folder (``save_pretrained`` output, ``hf://`` repository) gives its ``model.safetensors``.
    """
    from semattnet.weights import WEIGHTS_NAME, fetch, get_weights, list_pretrained

    path = Path(spec).expanduser()
    if spec in list_pretrained():
        path = fetch(get_weights(spec), progress=progress)
    elif "://" in spec:
        path = fetch(spec, progress=progress)
    elif not path.exists():
        known = ", ".join(list_pretrained())
        raise click.BadParameter(
            f"{spec!r} is not a file, a URL or a registered name ({known})", param_hint="--weights"
        )
    if path.is_dir():
        path = path / WEIGHTS_NAME
        if not path.is_file():
            raise click.BadParameter(f"{spec}: folder without {WEIGHTS_NAME}", param_hint="--weights")
    return path


@main.group()
def weights() -> None:
    """Released weights: list the registry, download into the verified cache."""


@weights.command("list")
def weights_list() -> None:
    """Table of released weights: architecture, size, file, checksum, licence and the paper's RMSE."""
    header = ("name", "arch", "params", "file", "sha256", "licence", "paper RMSE")
    click.echo(_table(header, _rows()))


@weights.command("fetch")
@click.argument("name")
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def weights_fetch(name: str, progress: bool) -> None:
    """Download NAME (a registry name or URL) into the cache; print its path and sha256."""
    from semattnet.weights import DownloadError, sha256_file

    try:
        path = weights_file(name, progress=progress)
    except DownloadError as exc:
        raise click.ClickException(f"{exc} (run the same command again to resume)") from None
    click.echo(f"path:   {path}")
    click.echo(f"sha256: {sha256_file(path)}")
