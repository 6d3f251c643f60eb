"""The frame loop's contract is written, not probed: what a source says beyond its frames is its ``info``
(:class:`~semattnet.data.frames.SourceInfo`), a two-stage source is a declared
:class:`~semattnet.data.frames.TwoStageSource`, the loop finds sinks by their ``role``, not their class, and
asks a completer only what :class:`~semattnet.inference.pipeline.Completer` declares."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

import semattnet
from semattnet._errors import InputError
from semattnet.baselines import ClassicalCompleter
from semattnet.data.frames import Frame, IndexedSource, SourceInfo, TwoStageSource
from semattnet.data.sources.semantic import MapSegmenter
from semattnet.inference import Completion
from semattnet.inference.pipeline import Completer, check_frames
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sinks import Prediction, Sink
from semattnet.inference.timing import StageTimes
from semattnet.palette import PaletteMismatchError

SIZE = (16, 24)
SRC = Path(semattnet.__file__).parent
#: The modules of the frame path: the loop, its reader, the semantic maps and the sources and sinks it reads.
FRAME_PATH = [
    "inference/pipeline.py",
    "inference/plan.py",
    "inference/loop.py",
    "inference/feed.py",
    "inference/semantic.py",
    "inference/sinks/base.py",
    "inference/sinks/files.py",
    "inference/sinks/latency.py",
    "data/datasets/frames.py",
    "evaluation/evaluate.py",
    "evaluation/split.py",
    "evaluation/sparsity.py",
]


def _frame(name: str) -> Frame:
    sparse = np.zeros(SIZE, np.float32)
    sparse[::4, ::4] = 4.0
    return Frame(name, np.full((*SIZE, 3), 90, np.uint8), sparse)


class Stamped(IndexedSource):
    """Frames with no timestamp of their own; the source knows every frame's sensor stamp (0.1 s apart)."""

    names = ("a", "b", "c")

    @property
    def info(self) -> SourceInfo:
        return SourceInfo(stamps_ns=[0, 100_000_000, 200_000_000])

    def load(self, name: str) -> Frame:
        return _frame(name)

    def inputs(self) -> list[Path]:
        return []


class TwoStage(Stamped):
    """Its frames read in two stages (decode, then assemble)."""

    def read(self, name: str) -> str:
        return name

    def assemble(self, raw: str) -> Frame:
        return _frame(raw)


@dataclass
class TextDepth(Sink):
    """The frame's depth file, under another class than the depth PNG's: ``NAME.txt``."""

    suffix: str = ".txt"
    role: ClassVar[str] = "depth"

    def save(self, path: Path, pred: Prediction) -> None:
        path.write_text(f"{pred.stored.mean():.2f}")


def test_the_loop_reads_the_sources_info_and_stages(tmp_path: Path) -> None:
    timer, lines = StageTimes(), []
    assert isinstance(TwoStage(), TwoStageSource) and not isinstance(Stamped(), TwoStageSource)
    run = check_frames(TwoStage(), [TextDepth()], tmp_path / "out").run(
        ClassicalCompleter(), timer=timer, log=lines.append
    )
    assert timer.stamps == {"a": 0.0, "b": 0.1, "c": 0.2} and timer.sensor_period_s == pytest.approx(0.1)
    assert all("projection" in timer.times[n] for n in "abc")  # assemble timed apart from read
    assert run.paths == [tmp_path / "out" / f"{n}.txt" for n in "abc"]  # the sink whose role is depth
    assert lines[0].endswith(f"-> {tmp_path / 'out' / 'a.txt'}")


class Indoor:
    """A completer written against the protocol alone: it takes NYU-40 maps, and records the ones it gets."""

    needs_semantic, palette, device = True, "nyu40", "cpu"

    def __init__(self) -> None:
        self.semantic: list[np.ndarray | None] = []

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        self.semantic.append(semantic)
        return Completion(np.where(sparse > 0, sparse, 5.0).astype(np.float32))


class CityscapesMaps(Stamped):
    """Frames whose semantic maps are of the Cityscapes palette."""

    @property
    def info(self) -> SourceInfo:
        return SourceInfo(palette="cityscapes")


def test_the_loop_runs_a_completer_by_its_protocol(tmp_path: Path) -> None:
    completer = Indoor()
    assert isinstance(completer, Completer)
    with pytest.warns(UserWarning, match="fallback map"):
        run = check_frames(Stamped(), [TextDepth()], tmp_path / "out").run(completer, log=lambda s: None)
    assert [p.name for p in run.paths] == ["a.txt", "b.txt", "c.txt"]
    assert len(completer.semantic) == 3 and all(m is not None and m.shape == (*SIZE, 3) for m in completer.semantic)
    with pytest.raises(PaletteMismatchError, match="NYU"):  # its palette, not a default, decides
        check_frames(CityscapesMaps(), [TextDepth()], tmp_path / "city").run(completer, log=lambda s: None)


def test_a_callable_that_does_not_say_what_it_needs_is_refused_in_one_line(tmp_path: Path) -> None:
    def bare(rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        return Completion(sparse)

    with pytest.raises(InputError, match=r"completer: a function is not a Completer: it must say its needs_semantic"):
        check_frames(Stamped(), [TextDepth()], tmp_path / "out").run(bare, log=lambda s: None)  # type: ignore[arg-type]
    assert not (tmp_path / "out" / "a.txt").exists()


class Labels:
    """A segmenter of Cityscapes class ids: every pixel is road (0)."""

    palette = "cityscapes"

    def __call__(self, images: np.ndarray, /) -> np.ndarray:
        return np.zeros(images.shape[:3], np.uint8)


def test_the_segmenters_palette_is_asked_not_assumed(tmp_path: Path) -> None:
    assert isinstance(Labels(), MapSegmenter)
    with pytest.raises(PaletteMismatchError, match="the segmenter's maps"):  # Cityscapes ids for an NYU-40 model
        check_frames(Stamped(), [TextDepth()], tmp_path / "out").run(
            Indoor(), semantic=SemanticMaps(Labels()), log=lambda s: None
        )
    with pytest.raises(InputError, match="semantic: a function is not a segmenter: it must say the palette"):
        SemanticMaps(lambda images: np.zeros(images.shape[:3], np.uint8))  # type: ignore[arg-type]


def test_no_probe_of_sources_sinks_or_completers_in_the_frame_path() -> None:
    """No ``getattr`` / ``hasattr`` on a source, a sink, a completer or a segmenter, no ``isinstance`` against a
    sink class."""
    found = []
    for rel in FRAME_PATH:
        for node in ast.walk(ast.parse((SRC / rel).read_text())):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.args):
                continue
            first, name = ast.unparse(node.args[0]), node.func.id
            probed = name in ("getattr", "hasattr") and any(
                w in first for w in ("source", "sink", "ds", "completer", "segmenter")
            )
            by_class = name == "isinstance" and len(node.args) > 1 and "Sink" in ast.unparse(node.args[1])
            if probed or by_class:
                found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "\n".join(found)
