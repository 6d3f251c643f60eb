"""The one place that decides a frame's semantic map when its source has none."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

from semattnet._errors import InputError
from semattnet.data.frames import Frame, IndexedSource

__all__ = ["MISMATCH_POLICIES", "CrossPaletteSource", "SemanticMaps"]


class SemanticMaps:
    """Fills the semantic map of frames whose source gave none, for a completer that needs one
    (:func:`semattnet.inference.backends.needs_semantic`): from ``segmenter`` (a
    :class:`semattnet.segmentation.Segmenter` or its SPEC, loaded on the completer's device when bound),
    else the ``unknown`` fallback map (warned once: it costs accuracy). A frame's own map is kept; for a
    completer that needs none the frame passes as it is.

    ``folder``: whether the source reads semantic maps from a folder (a folder and a segmenter exclude
    each other; checked here, before any work). :meth:`bind` the completer before :meth:`fill`.
    """

    def __init__(self, segmenter: Any = None, folder: bool = False) -> None:
        if folder and segmenter is not None:
            raise InputError("semantic: give a semantic folder or a segmenter, not both")
        self.segmenter, self.folder, self.needed = segmenter, folder, False
        self._warned = False

    def bind(self, completer: Any) -> SemanticMaps:
        """Decide for ``completer``: whether it needs maps; a segmenter SPEC is loaded on its device."""
        from semattnet.inference.backends import needs_semantic

        self.needed = needs_semantic(completer)
        if self.needed and isinstance(self.segmenter, str):
            from semattnet.segmentation.segmenter import load_segmenter

            self.segmenter = load_segmenter(self.segmenter, getattr(completer, "device", "auto"))
        return self

    def check_palette(self, completer: Any, source: Any) -> None:
        """Refuse maps of another palette than the one ``completer``'s model was trained with (one line;
        :func:`semattnet.data.palette.check_palette`): a segmenter's maps are of its ``palette`` (Cityscapes
        unless it says otherwise), a source's of its ``palette`` (None: it gives none, and the fallback map fits
        every palette)."""
        from semattnet.data.palette import check_palette

        if not self.needed:
            return
        palette = getattr(self.segmenter, "palette", "cityscapes") if self.segmenter is not None else (
            getattr(source, "palette", None))  # fmt: skip
        palette = palette or ("cityscapes" if self.folder else None)
        if palette is not None:
            where = "the segmenter's maps" if self.segmenter is not None else f"{type(source).__name__} maps"
            check_palette(getattr(completer, "palette", "cityscapes"), palette, where)

    def fill(self, frame: Frame) -> Frame:
        """``frame`` with the semantic map the completer gets."""
        from semattnet.data.palette import ids_to_colors, unknown_map

        if not self.needed or frame.semantic is not None:
            return frame
        if self.segmenter is not None:
            palette = getattr(self.segmenter, "palette", "cityscapes")
            return frame.with_semantic(ids_to_colors(self.segmenter(frame.rgb[None])[0], palette))
        if not self._warned:
            warnings.warn("no semantic maps given (--semantic or --segment): using the 'unknown' fallback map, "
                          "which costs accuracy", stacklevel=3)  # fmt: skip
            self._warned = True
        return frame.with_semantic(unknown_map(*frame.rgb.shape[:2]))


#: ``--palette-mismatch`` policies: refuse (the default), recolour, fallback.
MISMATCH_POLICIES = ("refuse", "recolour", "fallback")


class CrossPaletteSource(IndexedSource):
    """``source``'s frames with maps in ``palette`` (a model's) instead of the source's own: recoloured
    (:func:`semattnet.data.palette.recolor`, ``recolour``: the classes both palettes name keep their meaning,
    the rest become unknown) or replaced by the fallback map (``fallback``; also when no class maps)."""

    def __init__(self, source: Any, palette: str, policy: str = "recolour") -> None:
        from semattnet.data.palette import get_palette, palette_mapping

        self.source, self.maps_palette = source, get_palette(source.palette).name
        self.palette = get_palette(palette).name
        self.kept = sorted(get_palette(self.maps_palette).classes[i - get_palette(self.maps_palette).first_id][0]
                           for i in palette_mapping(self.maps_palette, self.palette))  # fmt: skip
        self.policy = "recolour" if policy == "recolour" and self.kept else "fallback"
        self.names = source.names

    def load(self, name: str) -> Frame:
        from semattnet.data.palette import recolor, unknown_map

        frame = self.source.load(name)
        if frame.semantic is None:
            return frame
        if self.policy == "fallback":
            return frame.with_semantic(unknown_map(*frame.semantic.shape[:2]))
        where = str(frame.paths.get("semantic", name)) if frame.paths else name
        return frame.with_semantic(recolor(frame.semantic, self.maps_palette, self.palette, where))

    def inputs(self) -> list[Path]:
        return list(self.source.inputs())

    def report(self) -> dict[str, Any]:
        """What the frames' maps became (metrics.json's ``semantic``), with a one-line ``summary``."""
        from semattnet.data.palette import get_palette

        src, dst = get_palette(self.maps_palette).title, get_palette(self.palette).title
        if self.policy == "recolour":
            line = (f"{src} maps recoloured to the model's {dst} palette: {', '.join(self.kept)} kept, every other "
                    "class unknown")  # fmt: skip
        else:
            line = f"{src} maps replaced by the fallback (unknown) map: the model was trained with {dst}"
        return {"maps_palette": self.maps_palette, "model_palette": self.palette, "used": self.policy,
                "classes_kept": self.kept if self.policy == "recolour" else [], "summary": line}  # fmt: skip
