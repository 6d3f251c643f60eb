"""The frames ``semattnet adapt`` learns from: any :class:`~semattnet.data.frames.FrameSource`, read as ``predict``
reads it (:func:`semattnet.inference.feed.read_frame`: the semantic map filled for the model), with the other
views of a :class:`~semattnet.data.frames.ViewSource`.

Every frame is read once before training: a frame that fails to read (its own fault,
:func:`~semattnet.inference.feed.is_frame_fault`) or has no LiDAR point is skipped with one line and counted as
``predict`` skips it (``on_error="skip"``), or stops the run (``"stop"``). Frames with ground truth may be held
out for the metric; the others are kept in a bounded cache and read again when it has dropped them.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import replace

from semattnet._errors import DataError
from semattnet.data.frames import Frame, FrameSource, ViewSource
from semattnet.inference.feed import FrameFault, is_frame_fault, read_frame
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.timing import StageTimes

__all__ = ["FramePool"]

#: Frames kept decoded in memory (a KITTI frame with its partner: ~6 MB).
CACHE_FRAMES = 64


class FramePool:
    """The usable frames of ``source``.

    Args:
        source: the frames (any registered source). semantic: the filler of missing semantic maps, bound to the
            model (None: frames as the source gives them).
        on_error: ``skip`` (one line per bad frame, counted in :attr:`faults`) or ``stop`` (the first one raises).
        held_out: how many frames with ground truth to keep out of training for the metric (the last ones).
        log: where the skip lines go.

    Raises:
        DataError: no usable frame is left (or ``stop`` and a bad frame).
    """

    def __init__(
        self,
        source: FrameSource,
        semantic: SemanticMaps | None,
        on_error: str = "skip",
        held_out: int = 0,
        log: Callable[[str], None] = print,
    ) -> None:
        self.source, self.semantic, self.log = source, semantic, log
        self.faults: list[FrameFault] = []
        self._cache: OrderedDict[str, Frame] = OrderedDict()
        sizes, with_gt = self._survey(on_error)
        if not sizes:
            raise DataError(f"{type(source).__name__}: none of its {len(source.names)} frame(s) can be read")
        self.held_out: list[str] = with_gt[-held_out:] if held_out else []
        self.names: list[str] = [n for n in sizes if n not in self.held_out]
        if not self.names:
            raise DataError(f"{len(sizes)} usable frame(s), all held out for the metric: hold out fewer")
        self.sizes = [sizes[n] for n in self.names]

    def _survey(self, on_error: str) -> tuple[dict[str, tuple[int, int]], list[str]]:
        """Read every frame once: ``({name: (H, W)} of the usable ones, [names with ground truth])``."""
        sizes: dict[str, tuple[int, int]] = {}
        with_gt: list[str] = []
        for name in self.source.names:
            try:
                frame = self._read(name)
            except Exception as exc:
                if not is_frame_fault(exc) or on_error == "stop":
                    raise
                reason = " ".join(str(exc).split()) or type(exc).__name__
                self.faults.append(FrameFault(name, "skipped", reason))
                self.log(f"{name}: skipped: {reason}")  # as predict says it
                continue
            sizes[name] = frame.size
            if frame.gt is not None and (frame.gt > 0).any():
                with_gt.append(name)
            self._keep(frame)
        return sizes, with_gt

    def _read(self, name: str) -> Frame:
        """One frame with its semantic map and views; a frame without any LiDAR point is its fault."""
        frame = read_frame(self.source, name, self.semantic, StageTimes())
        if not (frame.sparse > 0).any():
            raise DataError(
                f"{frame.paths.get('sparse') or frame.paths.get('scan') or name}: no LiDAR point in the image"
            )
        if isinstance(self.source, ViewSource):
            frame = replace(frame, views=self.source.views(name))
        return frame

    def _keep(self, frame: Frame) -> None:
        self._cache[frame.name] = frame
        self._cache.move_to_end(frame.name)
        while len(self._cache) > CACHE_FRAMES:
            self._cache.popitem(last=False)

    def frame(self, name: str) -> Frame:
        """Frame ``name`` (from the cache, else read again)."""
        if name not in self._cache:
            self._keep(self._read(name))
        self._cache.move_to_end(name)
        return self._cache[name]

    def frames(self, names: Sequence[str]) -> list[Frame]:
        return [self.frame(n) for n in names]
