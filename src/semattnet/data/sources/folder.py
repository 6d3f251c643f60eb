"""A user's frames from files: image, sparse depth and (optional) semantic map paired by name."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from semattnet._utils.registry import OptionError, option
from semattnet.data.frames import Frame, IndexedSource, unique_names
from semattnet.data.io import read_depth, read_image, read_semantic
from semattnet.data.pairing import FramePaths, pair_frames
from semattnet.data.sources.registry import SourceOptions, register_source

__all__ = ["FolderOptions", "FolderSource"]


@dataclass(frozen=True)
class FolderOptions(SourceOptions):
    """``--rgb`` / ``--sparse`` (and ``--K``): the user's own files or folders, paired by name."""

    heading: ClassVar[str] = "Inputs: files"
    usage: ClassVar[str] = "--rgb and --sparse"
    selects: ClassVar[tuple[str, ...]] = ("rgb", "sparse")
    accepts: ClassVar[tuple[str, ...]] = ("semantic",)
    report: ClassVar[bool] = True

    rgb: Path | None = option("--rgb", type="input", help="PNG file or folder (with --sparse).")
    sparse: Path | None = option("--sparse", type="input", help="16-bit PNG file or folder (with --rgb).")
    intrinsics: str | None = option(
        "--K",
        metavar="fx,fy,cx,cy|kitti",
        help="The camera's intrinsics ('kitti': KITTI's camera 02): for --report's 3D "
        "view and the clouds of --bag-out, --rerun and --live.",
    )

    def check(self, segment_spec: str | None) -> None:
        if self.rgb is None or self.sparse is None:
            raise OptionError("--rgb and --sparse go together: give both")
        self.camera_matrix()

    def camera_matrix(self) -> np.ndarray | None:
        """``--K`` as a (3, 3) matrix, or None (a bad value: an :class:`OptionError` of ``--K``)."""
        from semattnet._errors import SemAttNetError
        from semattnet.geometry.cameras import parse_intrinsics

        try:
            return parse_intrinsics(self.intrinsics) if self.intrinsics else None
        except SemAttNetError as exc:
            raise OptionError(str(exc), "--K") from None
        except ValueError:
            raise OptionError(f"expected fx,fy,cx,cy or kitti, got {self.intrinsics!r}", "--K") from None

    def has_intrinsics(self) -> bool:
        return self.intrinsics is not None

    def source(self, semantic: Path | None, log: Callable[[str], None]) -> FolderSource:
        assert self.rgb is not None and self.sparse is not None  # checked
        return FolderSource.pair(self.rgb, self.sparse, semantic, K=self.camera_matrix(), missing_ok=True)


@register_source("folder", option="--rgb", options=FolderOptions)
class FolderSource(IndexedSource):
    """Frames from :class:`~semattnet.data.pairing.FramePaths` (``FolderSource.pair(rgb, sparse, semantic)``
    pairs files or folders by name). ``K``: the (3, 3) intrinsics of every frame, if known.
    ``given``: the paths the user named (files or folders), protected from outputs too."""

    def __init__(
        self,
        frames: Sequence[FramePaths],
        K: np.ndarray | None = None,
        given: Sequence[str | os.PathLike[str] | None] = (),
    ) -> None:
        rgb = unique_names(((f.name, f.rgb) for f in frames), "frames")
        self.frames = {f.name: f for f in frames}
        self.names = list(rgb)
        self.K = None if K is None else np.asarray(K, dtype=np.float64)
        self.given = [Path(p) for p in given if p is not None]

    @classmethod
    def pair(
        cls,
        rgb: str | os.PathLike[str],
        sparse: str | os.PathLike[str],
        semantic: str | os.PathLike[str] | None = None,
        K: np.ndarray | None = None,
        missing_ok: bool = False,
    ) -> FolderSource:
        """The frames of ``rgb``/``sparse``/``semantic`` (three files or three folders), paired by name
        (``missing_ok``: an image without a partner is a frame that fails when read; see ``pair_frames``)."""
        sem = Path(semantic) if semantic is not None else None
        return cls(pair_frames(Path(rgb), Path(sparse), sem, missing_ok), K, given=(rgb, sparse, semantic))

    def load(self, name: str) -> Frame:
        f = self.frames[name]
        paths = {"rgb": f.rgb, "sparse": f.sparse} | ({"semantic": f.semantic} if f.semantic is not None else {})
        return Frame(
            name,
            read_image(f.rgb),
            read_depth(f.sparse),
            read_semantic(f.semantic) if f.semantic is not None else None,
            K=self.K,
            paths=paths,
        )

    def inputs(self) -> list[Path]:
        files = [p for f in self.frames.values() for p in (f.rgb, f.sparse, f.semantic) if p is not None]
        return [*files, *self.given]
