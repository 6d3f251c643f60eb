"""What a completer gives and what the frame loop asks of one: :class:`Completion`, the :class:`Completer`
protocol, :class:`CompleterFactory` (a completer built later) and :class:`StageTimed` (a completer that times its
inner stages). Below both the completer and the
feed (:mod:`~.feed`), so that each can name them."""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import torch

from semattnet.inference.backends._base import StageClock
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["Completer", "CompleterFactory", "Completion", "SelectsOutputs", "StageTimed", "reading_only"]


@dataclass
class Completion:
    """A completed frame: ``depth`` (H, W) float32 metres (the final prediction, as the method returned
    it) and ``output``, the model's typed :class:`DepthCompletionOutput` ((1, 1, H, W) CPU tensors), or
    None for a method without branches (the classical baseline); ``uncertainty`` the per-pixel
    uncertainty of ``depth``, (H, W) float32 metres."""

    depth: np.ndarray
    output: DepthCompletionOutput | None = None
    #: (H, W) float32 per-pixel uncertainty of ``depth`` in metres, or None when the method gives none:
    #: ``output.uncertainty`` (:func:`semattnet.models.uncertainty.depth_uncertainty`) when not given;
    #: the classical baseline's :func:`semattnet.baselines.classical.classical_uncertainty`.
    uncertainty: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.uncertainty is None and self.output is not None and self.output.uncertainty is not None:
            self.uncertainty = self.output.uncertainty[0, 0].float().cpu().numpy()

    @property
    def outputs(self) -> dict[str, np.ndarray]:
        """Every map as an (H, W) array by field name (``{"refined_depth": depth}`` without ``output``):
        what the panels and the viewer draw."""
        if self.output is None:
            return {"refined_depth": np.asarray(self.depth, dtype=np.float32)}
        return {k: v[0, 0].float().cpu().numpy() for k, v in self.output.to_dict().items()}

    @property
    def confidence(self) -> np.ndarray | None:
        """(H, W) largest of the fusion weights of eq. 12 (the method's confidence), or None without branches (or
        from an engine not asked for them)."""
        if self.output is None:
            return None
        confs = [
            c for c in (self.output.color_conf, self.output.semantic_conf, self.output.guided_conf) if c is not None
        ]
        if not confs:
            return None
        return torch.stack([c[0, 0].float().cpu() for c in confs]).amax(0).numpy()


@runtime_checkable
class Completer(Protocol):
    """What the frame loop runs (:class:`DepthCompleter`, :class:`semattnet.baselines.ClassicalCompleter`):
    called as ``completer(rgb, sparse, semantic)`` -> :class:`Completion`, and saying whether it takes a
    semantic map, of which palette, and the device a segmenter for it runs on. Everything the loop asks of it."""

    @property
    def needs_semantic(self) -> bool:
        """Whether a call takes a semantic map (the loop then gives every frame one)."""
        ...

    @property
    def palette(self) -> str:
        """The palette of the semantic maps it reads (:mod:`semattnet.palette`; maps of another are refused)."""
        ...

    @property
    def device(self) -> str | torch.device:
        """Where it runs: a segmenter loaded for its maps runs there too."""
        ...

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion: ...


@dataclass(frozen=True)
class CompleterFactory:
    """A completer built later: ``build()`` is called once every input and output is checked, so that a bad input
    is reported before a model is loaded (what ``evaluate_split``, the sparsity sweep and ``write_submission``
    accept besides a completer), e.g. ``CompleterFactory(lambda: DepthCompleter.from_pretrained(name))``."""

    build: Callable[[], Completer]


@runtime_checkable
class StageTimed(Protocol):
    """A completer that times the stages it runs inside a call (e.g. ``propagation``) through a hook."""

    def timing(self, hook: StageClock) -> AbstractContextManager[tuple[str, ...]]:
        """While active, the inner stages of every call run inside ``hook(stage)``; gives those stages (empty:
        the call is not split)."""
        ...


@runtime_checkable
class SelectsOutputs(Protocol):
    """A completer that computes only the outputs it is told are read (:attr:`DepthCompleter.outputs
    <semattnet.inference.completer.DepthCompleter.outputs>`): fields of
    :class:`~semattnet.models.outputs.DepthCompletionOutput`, None for all."""

    @property
    def outputs(self) -> frozenset[str] | None: ...

    @outputs.setter
    def outputs(self, names: Collection[str] | None) -> None: ...


@contextmanager
def reading_only(completer: object, outputs: Collection[str] | None) -> Iterator[None]:
    """While active, ``completer`` (when it :class:`SelectsOutputs`) computes only ``outputs`` (None: all; what the
    frame loop's sinks read, :func:`~semattnet.inference.sinks.outputs_read`); its own setting is put back after."""
    if not isinstance(completer, SelectsOutputs) or outputs is None:
        yield
        return
    before = completer.outputs
    completer.outputs = outputs
    try:
        yield
    finally:
        completer.outputs = before
