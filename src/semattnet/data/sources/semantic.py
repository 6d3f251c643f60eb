"""Semantic maps of another palette than the model's: refused, recoloured or replaced (``--palette-mismatch``).

Which map a frame gets when its source has none is decided in :mod:`semattnet.inference.semantic`."""

from __future__ import annotations

from typing import Protocol, TypedDict, runtime_checkable

import numpy as np

__all__ = ["MISMATCH_POLICIES", "CrossPalette", "MapSegmenter", "PaletteReport"]


@runtime_checkable
class MapSegmenter(Protocol):
    """What the frame loop asks of a segmenter (a :class:`semattnet.segmentation.Segmenter`): called on
    (B, H, W, 3) uint8 images -> (B, H, W) uint8 class ids of its ``palette``."""

    @property
    def palette(self) -> str:
        """The palette its class ids are of (:mod:`semattnet.palette`)."""
        ...

    def __call__(self, images: np.ndarray, /) -> np.ndarray: ...


class PaletteReport(TypedDict):
    """What :class:`CrossPalette` made of the frames' maps (``metrics.json``'s ``semantic``)."""

    maps_palette: str
    model_palette: str
    used: str
    classes_kept: list[str]
    summary: str


#: ``--palette-mismatch`` policies: refuse (the default), recolour, fallback.
MISMATCH_POLICIES = ("refuse", "recolour", "fallback")


class CrossPalette:
    """Maps of ``maps_palette`` given to a model of ``palette``: recoloured (``recolour``;
    :func:`semattnet.palette.recolor`: the classes both palettes name keep their meaning, the rest become
    unknown) or replaced by the fallback map (``fallback``; also when no class maps)."""

    def __init__(self, maps_palette: str, palette: str, policy: str = "recolour") -> None:
        from semattnet.palette import get_palette, palette_mapping

        src = get_palette(maps_palette)
        self.maps_palette, self.palette = src.name, get_palette(palette).name
        self.kept = sorted(src.classes[i - src.first_id][0] for i in palette_mapping(src.name, self.palette))
        self.policy = "recolour" if policy == "recolour" and self.kept else "fallback"

    def map(self, semantic: np.ndarray, where: str = "semantic map") -> np.ndarray:
        """One map converted."""
        from semattnet.palette import recolor, unknown_map

        if self.policy == "fallback":
            return unknown_map(*semantic.shape[:2])
        return recolor(semantic, self.maps_palette, self.palette, where)

    def report(self) -> PaletteReport:
        """What the frames' maps became (metrics.json's ``semantic``), with a one-line ``summary``."""
        from semattnet.palette import get_palette

        src, dst = get_palette(self.maps_palette).title, get_palette(self.palette).title
        if self.policy == "recolour":
            line = (
                f"{src} maps recoloured to the model's {dst} palette: {', '.join(self.kept)} kept, every other "
                "class unknown"
            )
        else:
            line = f"{src} maps replaced by the fallback (unknown) map: the model was trained with {dst}"
        return {
            "maps_palette": self.maps_palette,
            "model_palette": self.palette,
            "used": self.policy,
            "classes_kept": self.kept if self.policy == "recolour" else [],
            "summary": line,
        }
