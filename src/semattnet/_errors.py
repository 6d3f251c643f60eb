"""The root of semattnet's error types.

Every error the library raises for bad input (a missing or corrupt file, a wrong shape, an unsafe
checkpoint) derives from :class:`SemAttNetError`, which is a ``ValueError`` so that existing
``except ValueError`` code keeps working. The subclasses live with the code that raises them:
``semattnet.data.io.DataError``, ``semattnet.data.palette.UnknownColorError``,
``semattnet.weights.CheckpointError`` / ``StateDictMismatchError`` / ``UnsafeCheckpointError``,
``semattnet.evaluation.SubmissionError``.
"""

from __future__ import annotations

__all__ = ["SemAttNetError"]


class SemAttNetError(ValueError):
    """Bad input to semattnet; the message names the file, tensor or option and what is wrong."""
