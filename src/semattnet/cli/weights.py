"""``semattnet weights list`` / ``weights fetch``: the released-weights registry and the download cache."""

from __future__ import annotations

import click

from semattnet.cli._group import main


@main.group()
def weights() -> None:
    """Released weights: list the registry, download into the verified cache."""


@weights.command("list")
def weights_list() -> None:
    """Table of released weights: architecture, size, file, checksum, licence and the paper's RMSE."""
    from semattnet.weights.listing import weights_table

    click.echo(weights_table())


@weights.command("fetch")
@click.argument("name")
@click.option("--progress/--no-progress", default=True, help="Show a progress bar.")
def weights_fetch(name: str, progress: bool) -> None:
    """Download NAME (a registry name or URL) into the cache; print its path and sha256."""
    from semattnet.cli._options import weights_path
    from semattnet.weights import DownloadError, sha256_file

    try:
        path = weights_path(name, progress=progress)
    except DownloadError as exc:
        raise click.ClickException(f"{exc} (run the same command again to resume)") from None
    click.echo(f"path:   {path}")
    click.echo(f"sha256: {sha256_file(path)}")
