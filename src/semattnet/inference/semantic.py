"""The one place that decides a frame's semantic map when its source has none (a segmenter, the fallback
map), for the completer at hand."""

from __future__ import annotations

import warnings

import numpy as np

from semattnet._errors import InputError
from semattnet.data.frames import Frame, FrameSource
from semattnet.data.sources.semantic import CrossPalette, MapSegmenter
from semattnet.inference.contract import Completer

__all__ = ["SemanticMaps"]


class SemanticMaps:
    """Fills the semantic map of frames whose source gave none, for a completer that needs one
    (:func:`semattnet.inference.backends.needs_semantic`): from ``segmenter`` (a
    :class:`semattnet.segmentation.Segmenter` or its SPEC, loaded on the completer's device when bound),
    else the ``unknown`` fallback map (warned once: it costs accuracy). A frame's own map is kept; for a
    completer that needs none the frame passes as it is.

    ``folder``: whether the source reads semantic maps from a folder (a folder and a segmenter exclude
    each other; checked here, before any work). ``mismatch``: maps of another palette than the model's are
    refused (``refuse``), or converted (``recolour`` / ``fallback``: :class:`CrossPalette`; ``note`` then
    says what they became). :meth:`bind` the completer before :meth:`fill`.
    """

    def __init__(
        self, segmenter: MapSegmenter | str | None = None, folder: bool = False, mismatch: str = "refuse"
    ) -> None:
        if folder and segmenter is not None:
            raise InputError("semantic: give a semantic folder or a segmenter, not both")
        if not (segmenter is None or isinstance(segmenter, str | MapSegmenter)):
            raise InputError(
                f"semantic: a {type(segmenter).__name__} is not a segmenter: it must say the palette "
                "of its maps (as semattnet.segmentation.Segmenter does)"
            )
        self.segmenter, self.folder, self.needed = segmenter, folder, False
        self.mismatch = mismatch
        self.cross: CrossPalette | None = None
        self.note: str | None = None
        self._warned = False
        self._fallback: np.ndarray | None = None  # the last fallback map, read-only, shared by frames of its size

    def bind(self, completer: Completer) -> SemanticMaps:
        """Decide for ``completer``: whether it needs maps; a segmenter SPEC is loaded on its device."""
        if not isinstance(completer, Completer):
            raise InputError(
                f"completer: a {type(completer).__name__} is not a Completer: it must say its "
                "needs_semantic, palette and device (as ClassicalCompleter does)"
            )
        self.needed = bool(completer.needs_semantic)
        if self.needed and isinstance(self.segmenter, str):
            from semattnet.segmentation.segmenter import load_segmenter

            self.segmenter = load_segmenter(self.segmenter, completer.device)
        return self

    def check_palette(self, completer: Completer, source: FrameSource) -> None:
        """Refuse maps of another palette than the one ``completer``'s model was trained with (one line;
        :func:`semattnet.palette.check_palette`): a segmenter's maps are of its ``palette``, a source's of its
        ``info.palette`` (None: it gives none, and the fallback map fits every palette)."""
        from semattnet.palette import check_palette, get_palette

        if not self.needed:
            return
        if isinstance(self.segmenter, str):  # bind, which decides ``needed``, loads it
            raise InputError(f"semantic: segmenter {self.segmenter!r} is not loaded; bind the completer first")
        palette = source.info.palette if self.segmenter is None else self.segmenter.palette
        palette = palette or ("cityscapes" if self.folder else None)
        if palette is not None:
            where = "the segmenter's maps" if self.segmenter is not None else f"{type(source).__name__} maps"
            model = completer.palette
            if self.mismatch != "refuse" and get_palette(palette).name != get_palette(model).name:
                self.cross = CrossPalette(palette, model, self.mismatch)
                self.note = self.cross.report()["summary"]
                return
            check_palette(model, palette, where)

    def fill(self, frame: Frame) -> Frame:
        """``frame`` with the semantic map the completer gets."""
        from semattnet.palette import ids_to_colors, unknown_map

        if not self.needed:
            return frame
        if frame.semantic is None and self.segmenter is not None:
            if isinstance(self.segmenter, str):  # bind loads it
                raise InputError(f"semantic: segmenter {self.segmenter!r} is not loaded; bind the completer first")
            frame = frame.with_semantic(ids_to_colors(self.segmenter(frame.rgb[None])[0], self.segmenter.palette))
        if frame.semantic is not None:
            return frame if self.cross is None else frame.with_semantic(self.cross.map(frame.semantic, frame.name))
        if not self._warned:
            warnings.warn(
                "no semantic maps given (--semantic or --segment): using the 'unknown' fallback map, "
                "which costs accuracy",
                stacklevel=3,
            )
            self._warned = True
        size = frame.rgb.shape[:2]
        if self._fallback is None or self._fallback.shape[:2] != size:  # made once per size, not per frame
            self._fallback = unknown_map(*size)
            self._fallback.flags.writeable = False
        return frame.with_semantic(self._fallback)
