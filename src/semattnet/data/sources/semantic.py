"""The one place that decides a frame's semantic map when its source has none."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TypedDict

import numpy as np

from semattnet._errors import InputError
from semattnet.data.frames import Frame, IndexedSource

__all__ = ["MISMATCH_POLICIES", "CrossPalette", "CrossPaletteSource", "MapSegmenter", "PaletteReport", "SemanticMaps"]

#: A segmenter: (B, H, W, 3) uint8 images -> (B, H, W) uint8 class ids (a
#: :class:`semattnet.segmentation.Segmenter`, whose ``palette`` names them; Cityscapes without one).
MapSegmenter = Callable[[np.ndarray], np.ndarray]


class PaletteReport(TypedDict):
    """What :class:`CrossPalette` made of the frames' maps (``metrics.json``'s ``semantic``)."""

    maps_palette: str
    model_palette: str
    used: str
    classes_kept: list[str]
    summary: str


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

    def __init__(self, segmenter: MapSegmenter | str | None = None, folder: bool = False,
                 mismatch: str = "refuse") -> None:  # fmt: skip
        if folder and segmenter is not None:
            raise InputError("semantic: give a semantic folder or a segmenter, not both")
        self.segmenter, self.folder, self.needed = segmenter, folder, False
        self.mismatch = mismatch
        self.cross: CrossPalette | None = None
        self.note: str | None = None
        self._warned = False

    def bind(self, completer: object) -> SemanticMaps:
        """Decide for ``completer``: whether it needs maps; a segmenter SPEC is loaded on its device."""
        from semattnet.inference.backends import needs_semantic

        self.needed = needs_semantic(completer)
        if self.needed and isinstance(self.segmenter, str):
            from semattnet.segmentation.segmenter import load_segmenter

            self.segmenter = load_segmenter(self.segmenter, getattr(completer, "device", "auto"))
        return self

    def check_palette(self, completer: object, source: object) -> None:
        """Refuse maps of another palette than the one ``completer``'s model was trained with (one line;
        :func:`semattnet.data.palette.check_palette`): a segmenter's maps are of its ``palette`` (Cityscapes
        unless it says otherwise), a source's of its ``palette`` (None: it gives none, and the fallback map fits
        every palette)."""
        from semattnet.data.palette import check_palette, get_palette

        if not self.needed:
            return
        palette = getattr(self.segmenter, "palette", "cityscapes") if self.segmenter is not None else (
            getattr(source, "palette", None))  # fmt: skip
        palette = palette or ("cityscapes" if self.folder else None)
        if palette is not None:
            where = "the segmenter's maps" if self.segmenter is not None else f"{type(source).__name__} maps"
            model = getattr(completer, "palette", "cityscapes")
            if self.mismatch != "refuse" and get_palette(palette).name != get_palette(model).name:
                self.cross = CrossPalette(palette, model, self.mismatch)
                self.note = self.cross.report()["summary"]
                return
            check_palette(model, palette, where)

    def fill(self, frame: Frame) -> Frame:
        """``frame`` with the semantic map the completer gets."""
        from semattnet.data.palette import ids_to_colors, unknown_map

        if not self.needed:
            return frame
        if frame.semantic is None and self.segmenter is not None:
            if isinstance(self.segmenter, str):  # bind loads it
                raise InputError(f"semantic: segmenter {self.segmenter!r} is not loaded; bind the completer first")
            palette = getattr(self.segmenter, "palette", "cityscapes")
            frame = frame.with_semantic(ids_to_colors(self.segmenter(frame.rgb[None])[0], palette))
        if frame.semantic is not None:
            return frame if self.cross is None else frame.with_semantic(self.cross.map(frame.semantic, frame.name))
        if not self._warned:
            warnings.warn("no semantic maps given (--semantic or --segment): using the 'unknown' fallback map, "
                          "which costs accuracy", stacklevel=3)  # fmt: skip
            self._warned = True
        return frame.with_semantic(unknown_map(*frame.rgb.shape[:2]))


#: ``--palette-mismatch`` policies: refuse (the default), recolour, fallback.
MISMATCH_POLICIES = ("refuse", "recolour", "fallback")


class CrossPalette:
    """Maps of ``maps_palette`` given to a model of ``palette``: recoloured (``recolour``;
    :func:`semattnet.data.palette.recolor`: the classes both palettes name keep their meaning, the rest become
    unknown) or replaced by the fallback map (``fallback``; also when no class maps)."""

    def __init__(self, maps_palette: str, palette: str, policy: str = "recolour") -> None:
        from semattnet.data.palette import get_palette, palette_mapping

        src = get_palette(maps_palette)
        self.maps_palette, self.palette = src.name, get_palette(palette).name
        self.kept = sorted(src.classes[i - src.first_id][0] for i in palette_mapping(src.name, self.palette))
        self.policy = "recolour" if policy == "recolour" and self.kept else "fallback"

    def map(self, semantic: np.ndarray, where: str = "semantic map") -> np.ndarray:
        """One map converted."""
        from semattnet.data.palette import recolor, unknown_map

        if self.policy == "fallback":
            return unknown_map(*semantic.shape[:2])
        return recolor(semantic, self.maps_palette, self.palette, where)

    def report(self) -> PaletteReport:
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


class CrossPaletteSource(IndexedSource):
    """``source``'s frames with their maps converted for a model of ``palette`` (:class:`CrossPalette`)."""

    def __init__(self, source: IndexedSource, palette: str, policy: str = "recolour") -> None:
        if source.palette is None:
            raise InputError(f"{type(source).__name__}: its frames have no semantic maps to convert to {palette}")
        self.source, self.cross = source, CrossPalette(source.palette, palette, policy)
        self.palette, self.names = self.cross.palette, source.names

    def load(self, name: str) -> Frame:
        frame = self.source.load(name)
        if frame.semantic is None:
            return frame
        where = str(frame.paths.get("semantic", name)) if frame.paths else name
        return frame.with_semantic(self.cross.map(frame.semantic, where))

    def inputs(self) -> list[Path]:
        return list(self.source.inputs())

    def report(self) -> PaletteReport:
        return self.cross.report()
