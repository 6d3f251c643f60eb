"""The ``semattnet`` command group and its error handling."""

from __future__ import annotations

import pickle

import click

from semattnet import __version__


class _Group(click.Group):
    """Turns the library's bad-input errors (a missing or corrupt file, a wrong size, an
    unsafe checkpoint, an existing output) into one-line CLI errors, for every command."""

    def invoke(self, ctx: click.Context):  # type: ignore[no-untyped-def]
        try:
            return super().invoke(ctx)
        except (ValueError, FileExistsError, pickle.UnpicklingError) as exc:
            raise click.ClickException(str(exc)) from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="semattnet")
def main() -> None:
    """SemAttNet depth completion: models, checkpoints and demos."""
