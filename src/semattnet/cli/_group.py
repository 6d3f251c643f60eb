"""The ``semattnet`` command group and its error handling."""

from __future__ import annotations

import errno
import os
import sys
import traceback
from importlib import metadata
from typing import Any

import click

from semattnet._errors import SemAttNetError
from semattnet._startup import restore_interrupts
from semattnet._utils.version import __version__

#: What to do about an operating-system error, by errno.
_ADVICE = {
    errno.EACCES: "check the folder's permissions or choose another --out",
    errno.EPERM: "check the folder's permissions or choose another --out",
    errno.EROFS: "the file system is read-only: choose another --out",
    errno.ENOSPC: "the disk is full: free space or write elsewhere (--out, or --cache-dir for downloads)",
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


#: Exit status of a command that failed on a bug of semattnet (``EX_SOFTWARE`` of sysexits.h).
BUG_EXIT_CODE = 70


def bug_report_line(exc: BaseException) -> str:
    """The line printed under the traceback of an unexpected exception: a bug, and where to report it."""
    where = "the semattnet issue tracker"
    try:
        urls = metadata.metadata("semattnet").get_all("Project-URL") or []
    except metadata.PackageNotFoundError:  # running from a source tree that is not installed
        urls = []
    for entry in urls:
        label, _, url = entry.partition(",")
        if label.strip().lower() in ("issues", "bug tracker", "tracker", "bugs"):
            where = url.strip()
    return (
        f"semattnet {__version__}: {type(exc).__name__} is a bug in semattnet, not a problem with your input; "
        f"please report it at {where} with the traceback above and the command you ran"
    )


#: The parameters that name a command's output, in the order a full disk without a path is blamed on them.
_OUTPUT_PARAMS = ("out", "out_dir", "bag_out", "rerun_file", "json_path")


class Command(click.Command):
    """A command whose full disk without a path (a plain write that filled it, a library's writer) is the
    one-line :func:`~semattnet._utils.atomic.disk_full_error` naming the command's output (``--out``, ...)."""

    def invoke(self, ctx: click.Context) -> Any:
        from semattnet._utils.atomic import disk_full_error, is_disk_full

        try:
            return super().invoke(ctx)
        except OSError as exc:
            where = next((ctx.params[k] for k in _OUTPUT_PARAMS if ctx.params.get(k) is not None), None)
            if not is_disk_full(exc) or getattr(exc, "filename", None) or where is None:
                raise
            raise disk_full_error(where) from None


class _Group(click.Group):
    """Error handling for every command.

    The library's bad-input errors (:class:`~semattnet.SemAttNetError`: a missing or corrupt file, a
    wrong size, an unsafe checkpoint, an option that means nothing) and operating-system errors (a
    read-only folder, a full disk, a path below a regular file, an existing output) become one-line
    CLI errors (exit status 1). Any other exception is a bug: its traceback is printed, then a line
    saying so and where to report it (exit status :data:`BUG_EXIT_CODE`).
    """

    command_class = Command
    group_class = type  # subgroups (``data``, ``weights``) are of this class too

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Python's SIGINT handler back (:mod:`semattnet._startup`), then the command."""
        restore_interrupts()
        return super().main(*args, **kwargs)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except (click.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except SemAttNetError as exc:  # includes UnsafeCheckpointError, the one UnpicklingError of ours
            raise click.ClickException(str(exc) or type(exc).__name__) from None
        except OSError as exc:
            raise click.ClickException(os_error_message(exc)) from None
        except Exception as exc:
            traceback.print_exc(file=sys.stderr)
            click.echo(bug_report_line(exc), err=True)
            ctx.exit(BUG_EXIT_CODE)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="semattnet")
def main() -> None:
    """SemAttNet depth completion: models, checkpoints and demos."""
