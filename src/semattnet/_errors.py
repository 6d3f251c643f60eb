"""The root of semattnet's error types: one home for the classes every subpackage raises.

Every error the library raises for bad input (a missing or corrupt file, a wrong shape, an unsafe
checkpoint, an option that means nothing) derives from :class:`SemAttNetError`, which is a
``ValueError`` so that existing ``except ValueError`` code keeps working. The command line turns a
:class:`SemAttNetError` (and an ``OSError``) into one line; anything else is a bug to report.

- :class:`DataError`: a data file is missing, unreadable or not in the expected encoding.
- :class:`InputError`: an argument (a tensor, an array, an option) is not what the function accepts.
- :class:`MissingDependencyError`: an optional dependency that the request needs is not installed.

More specific classes live with the code that raises them and derive from these (for example
``semattnet.palette.UnknownColorError``, ``semattnet.weights.CheckpointError``).
"""

from __future__ import annotations

__all__ = ["DataError", "InputError", "MissingDependencyError", "SemAttNetError"]


class SemAttNetError(ValueError):
    """Bad input to semattnet; the message names the file, tensor or option and what is wrong."""


class DataError(SemAttNetError):
    """A data file is missing, unreadable or not in the expected encoding."""


class InputError(SemAttNetError, TypeError):
    """An argument (tensor, array, option value or combination) that the function does not accept.

    Also a ``TypeError``, so code that caught the type errors of a wrong argument keeps working."""


class MissingDependencyError(ImportError, SemAttNetError):
    """An optional dependency the request needs is not installed; the message says what to install.

    An ``ImportError`` first (so ``name=`` and ``path=`` work as for ImportError), and a SemAttNetError."""
