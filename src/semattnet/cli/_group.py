"""The ``semattnet`` command group and its error handling."""

from __future__ import annotations

import errno
import os
import pickle

import click

from semattnet import __version__
from semattnet._errors import SemAttNetError

#: What to do about an operating-system error, by errno.
_ADVICE = {
    errno.EACCES: "check the folder's permissions or choose another --out",
    errno.EPERM: "check the folder's permissions or choose another --out",
    errno.EROFS: "the file system is read-only: choose another --out",
    errno.ENOSPC: "the disk is full: free space or choose another --out",
    errno.EDQUOT: "the disk quota is exceeded: free space or choose another --out",
    errno.ENOTDIR: "a part of the path is a file, not a folder: choose another path",
    errno.EEXIST: "it exists: pass --overwrite or choose another path",
    errno.EISDIR: "it is a folder: give a file path",
    errno.ENOENT: "check the path",
    errno.ENAMETOOLONG: "choose a shorter path",
}


def os_error_message(exc: OSError) -> str:
    """One line naming the path, the problem and what to do."""
    where = " -> ".join(str(p) for p in (exc.filename, exc.filename2) if p is not None)
    reason = exc.strerror or str(exc) or type(exc).__name__
    advice = _ADVICE.get(exc.errno or 0)
    text = f"{where}: {reason}" if where else reason
    if isinstance(exc, FileExistsError) and exc.errno is None:
        text = str(exc)  # the library's own message already says what to do
    elif advice:
        text = f"{text} ({advice})"
    return " ".join(text.split()) or os.strerror(exc.errno or 0)


class _Group(click.Group):
    """Turns the library's bad-input errors (a missing or corrupt file, a wrong size, an
    unsafe checkpoint, an existing output) and operating-system errors (a read-only folder,
    a full disk, a path below a regular file) into one-line CLI errors, for every command."""

    def invoke(self, ctx: click.Context):  # type: ignore[no-untyped-def]
        try:
            return super().invoke(ctx)
        except (click.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except (SemAttNetError, ValueError, pickle.UnpicklingError) as exc:
            raise click.ClickException(str(exc) or type(exc).__name__) from None
        except OSError as exc:
            raise click.ClickException(os_error_message(exc)) from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="semattnet")
def main() -> None:
    """SemAttNet depth completion: models, checkpoints and demos."""
