"""What a run of the one frame loop is told, typed: :class:`OutputSpec` (the output folder's rules) and
:class:`RunOptions` (how the frames are run). The library's side of ``semattnet predict``'s output and run
options (``--overwrite``, ``--resume``, ``--on-error``, ``--stream``, ``--realtime``/``--speed``)::

    plan = check_frames(source, sinks, "out", OutputSpec(overwrite=True), RunOptions(on_error="skip", prefetch=2))
    run = plan.run(completer)
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from semattnet._errors import InputError

__all__ = ["WRITE_AHEAD", "OutputSpec", "RunOptions"]

PathLike = str | os.PathLike[str]

#: Frames the writing runs behind the network by default in a paced or read-ahead run: the network completes frame
#: ``i + 1`` while frame ``i`` is written, so it is the only serial stage.
WRITE_AHEAD = 1


@dataclass(frozen=True)
class OutputSpec:
    """The output folder's rules (:mod:`semattnet._utils.outputs`).

    ``overwrite``: replace existing outputs. ``resume``: continue the run in the folder, keeping its done frames;
    ``run``: the run's identity, which must be the one recorded there. ``inputs``: further paths the user gave
    (files or folders; the weights) that outputs must stay out of.
    """

    overwrite: bool = False
    resume: bool = False
    run: Mapping[str, object] | None = None
    inputs: Sequence[PathLike | None] = ()


@dataclass(frozen=True)
class RunOptions:
    """How the frames are run.

    ``on_error``: a frame whose input cannot be read or completed is ``"skip"``-ped (one line) or ``"stop"``-s the
    run; None: ``skip`` for more than one frame. ``prefetch`` > 0: read, project and segment that many frames
    ahead in a background thread. ``realtime``: replay at the sensor pace, that many times faster, dropping frames
    that come while the completer is busy (None: every frame). ``batch_size`` > 1: up to that many consecutive
    frames of one size completed in one engine call. ``write_ahead``: how many completed frames the writing (every
    sink, the files moved into place, the journal) may run behind the network, in a background stage
    (:mod:`~.writer`); 0: each frame written before the next is completed; None: :data:`WRITE_AHEAD` frames with
    ``realtime`` or ``prefetch``, else 0. ``png_compress_level``: the zlib level (0-9) of the PNGs the sinks write
    (None: :meth:`png_level`'s default; the pixels are the same at every level).
    """

    on_error: str | None = None
    prefetch: int = 0
    realtime: float | None = None
    batch_size: int = 1
    write_ahead: int | None = None
    png_compress_level: int | None = None

    def __post_init__(self) -> None:
        level = self.png_compress_level
        if level is not None and not (isinstance(level, int) and 0 <= level <= 9):
            raise InputError(f"png_compress_level must be 0 to 9, got {level!r}")

    def write_depth(self) -> int:
        """``write_ahead`` as it applies (its default resolved)."""
        if self.write_ahead is None:
            return WRITE_AHEAD if self.realtime is not None or self.prefetch > 0 else 0
        if self.write_ahead < 0:
            raise InputError(f"write_ahead must be 0 or more, got {self.write_ahead!r}")
        return self.write_ahead

    def png_level(self) -> int:
        """``png_compress_level`` as it applies: as given, else :data:`~semattnet.data.io.STREAM_PNG_COMPRESS_LEVEL`
        when the writing runs beside the network (:meth:`write_depth` > 0: ``realtime`` or ``prefetch``), else
        :data:`~semattnet.data.io.PNG_COMPRESS_LEVEL`."""
        from semattnet.data.io import PNG_COMPRESS_LEVEL, STREAM_PNG_COMPRESS_LEVEL

        if self.png_compress_level is None:
            return STREAM_PNG_COMPRESS_LEVEL if self.write_depth() > 0 else PNG_COMPRESS_LEVEL
        return self.png_compress_level

    def policy(self, frames: int) -> str:
        """``on_error`` for a run of ``frames`` frames: as given, else ``skip`` for more than one and ``stop``
        for one."""
        if self.on_error is None:
            return "skip" if frames > 1 else "stop"
        if self.on_error not in ("skip", "stop"):
            raise InputError(f"on_error must be 'skip' or 'stop', got {self.on_error!r}")
        return self.on_error
