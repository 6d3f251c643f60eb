"""Depth completion for your own frames: NumPy in, NumPy out, any image size.

With trained weights: ``DepthCompleter.from_pretrained("semattnet-rt-generalist")`` (a name, a file, a folder or
a URL). Here a tiny untrained model shows the shapes:

    >>> import numpy as np, semattnet
    >>> completer = DepthCompleter(semattnet.build_model("semattnet", width=0.125), EngineSpec(device="cpu"))
    >>> rgb = np.zeros((50, 70, 3), np.uint8)              # (H, W, 3) 0..255
    >>> semantic = np.zeros((50, 70, 3), np.uint8)         # Cityscapes colours
    >>> sparse = np.zeros((50, 70), np.float32); sparse[40, 10] = 12.5   # metres, 0 = none
    >>> result = completer(rgb, sparse, semantic)
    >>> result.depth.shape, result.depth.dtype            # cropped back to the input size
    ((50, 70), dtype('float32'))

Frames are padded to multiples of 32 (rows at the top, columns on both sides) and the outputs
cropped back, so any size works, KITTI's 1242x375 included.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Iterator, Sequence
from contextlib import contextmanager
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.inference.backends import EngineSpec, needs_semantic, optimize_for_inference
from semattnet.inference.backends._base import InferenceEngine, StageClock
from semattnet.inference.contract import Completer, Completion, StageTimed
from semattnet.inference.padding import crop_padding, pad_to_multiple
from semattnet.models.checks import check_has_points, check_sparse_depth
from semattnet.models.generalist import Generalist
from semattnet.models.outputs import DepthCompletionOutput, check_output_names
from semattnet.models.uncertainty import outputs_to_compute, with_uncertainty
from semattnet.weights.hub import from_pretrained
from semattnet.weights.resolve import resolve_weights

if TYPE_CHECKING:
    from semattnet.data.frames import Frame, FrameSource
    from semattnet.inference.semantic import SemanticMaps
    from semattnet.inference.timing import StageTimes

__all__ = ["Completer", "Completion", "DepthCompleter", "EngineSpec", "StageClock", "StageTimed", "load_completer"]


def _item(t: torch.Tensor, i: int) -> torch.Tensor:
    """Item ``i`` of a batched (B, C, H, W) output, as a batch of one."""
    return t[i : i + 1]


def _batch(items: Sequence[torch.Tensor]) -> torch.Tensor:
    """Batches of one (B = 1) as one batch: the one as it is (no copy), else concatenated."""
    return items[0] if len(items) == 1 else torch.cat(list(items))


def _check_colour_range(name: str, a: np.ndarray | None) -> None:
    """``rgb`` / ``semantic`` hold 0..255 colours: NaN, infinite or out-of-range values are refused in one line."""
    if a is None or np.asarray(a).size == 0 or np.asarray(a).dtype == np.uint8:  # uint8: 0..255 by its type
        return
    try:
        v = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must hold numbers 0..255, got dtype {np.asarray(a).dtype}") from None
    if not np.all(np.isfinite(v)):
        raise InputError(f"{name} contains NaN or infinite values")
    lo, hi = float(v.min()), float(v.max())
    if lo < 0 or hi > 255:
        raise InputError(f"{name} must hold colours 0..255, got values in [{lo:g}, {hi:g}]")


#: The engine arguments ``DepthCompleter`` took one by one before :class:`EngineSpec` (accepted until 0.3, with a
#: ``DeprecationWarning``), in their old positional order after ``model``.
LEGACY_ENGINE_ARGS = ("device", "amp", "backend", "precision", "calibration")


def legacy_spec(given: dict[str, object], where: str) -> EngineSpec:
    """The :class:`EngineSpec` of the engine arguments given one by one (``device``, ``amp``, ``backend``,
    ``precision``, ``calibration``; deprecated in 0.2, removed in 0.3), with a ``DeprecationWarning`` naming
    ``where``."""
    import warnings

    unknown = set(given) - set(LEGACY_ENGINE_ARGS)
    if unknown:
        raise InputError(f"{where}: unknown argument(s) {sorted(unknown)}; give spec=EngineSpec(...)")
    warnings.warn(
        f"{where}({', '.join(f'{k}=' for k in given)}...): the engine's arguments one by one are deprecated since "
        "0.2 and go in 0.3; give spec=EngineSpec(device=..., backend=..., precision=...)",
        DeprecationWarning,
        stacklevel=3,
    )
    amp = str(given.get("amp", "none"))
    return EngineSpec(
        str(given.get("backend", "torch")),
        None if given.get("precision") is None else str(given["precision"]),
        given.get("device", "auto"),  # type: ignore[arg-type]
        given.get("calibration"),  # type: ignore[arg-type]
        None if amp == "none" else amp,
    )


class DepthCompleter:
    """A model ready for inference on NumPy frames of any size: ``DepthCompleter(model, spec)``, or
    :meth:`from_pretrained` for weights by name, file or URL.

    Args:
        model: a SemAttNet model (full or backbone, paper or real-time, or a generalist).
        spec: the engine (:class:`~semattnet.inference.backends.EngineSpec`: backend, precision, device, int8's
            calibration frames; default: ``torch``, f32, the best device). The ``torch`` backend folds BatchNorm
            and fuses the propagation; the fixed-size backends (``openvino``) build (and cache on disk) one engine
            per padded frame size, so they pay off over many frames of one size.
        inplace: fold ``model`` itself instead of a copy (saves memory; :meth:`from_pretrained` does).
        legacy: ``device``, ``amp``, ``backend``, ``precision``, ``calibration`` one by one (or positionally after
            ``model``), the older form: deprecated since 0.2, accepted until 0.3 (a ``DeprecationWarning``).

    Raises:
        InputError: a backend, precision and device that do not go together (:meth:`EngineSpec.resolve`), or a
            spec and the older arguments both.
    """

    def __init__(
        self,
        model: nn.Module,
        spec: EngineSpec | None = None,
        *args: object,
        inplace: bool = False,
        **legacy: object,
    ) -> None:
        if args or legacy or (spec is not None and not isinstance(spec, EngineSpec)):
            old = dict(zip(LEGACY_ENGINE_ARGS, (spec, *args), strict=False)) if spec is not None else {}
            if isinstance(spec, EngineSpec) or len(args) >= len(LEGACY_ENGINE_ARGS) or set(old) & set(legacy):
                raise InputError("DepthCompleter: give spec or device / amp / backend / precision / calibration")
            spec = legacy_spec(old | legacy, "DepthCompleter")
        spec = spec if spec is not None else EngineSpec()
        #: The engine's spec, resolved: a concrete backend, precision and device.
        self.spec = spec.resolve()
        self.device = torch.device(self.spec.device)
        self.backend, self.precision, self.calibration = self.spec.backend, self.spec.precision, spec.calibration
        self.amp = self.spec.autocast
        self.needs_semantic = needs_semantic(model)
        #: The semantic palette the model was trained with (its config's; Cityscapes when it records none).
        self.palette: str = getattr(getattr(model, "config", None), "palette", "cityscapes")
        #: Whether :meth:`run` (and a call) sets the outputs' ``uncertainty``
        #: (:func:`semattnet.models.uncertainty.depth_uncertainty`; about 60 ms of one CPU core at 375x1242), when
        #: :attr:`outputs` asks for it too.
        self.compute_uncertainty = True
        self._outputs: frozenset[str] | None = None
        model = model.to(self.device).eval()
        #: The generalist around the network the engines run (None: the model is the network).
        self.generalist: Generalist | None = model if isinstance(model, Generalist) else None
        self._source = model.net if isinstance(model, Generalist) else model
        self._inplace = inplace
        self._engines: dict[tuple[tuple[int, int] | None, frozenset[str] | None], InferenceEngine] = {}

    @classmethod
    def from_pretrained(
        cls,
        name_or_path: str | os.PathLike[str],
        spec: EngineSpec | None = None,
        *,
        sha256: str | None = None,
        cache_dir: str | os.PathLike[str] | None = None,
        progress: bool = True,
        arch: str | None = None,
        **overrides: object,
    ) -> DepthCompleter:
        """A completer for released weights by name, a local file or folder, or a URL, read by
        :func:`semattnet.weights.resolve_weights`, on the engine ``spec`` says
        (:func:`semattnet.weights.from_pretrained` explains ``sha256``, ``cache_dir``, ``progress``, ``arch`` and
        the config ``overrides``; ``device``, ``amp``, ``backend`` among them: the older form, deprecated)."""
        old = {k: overrides.pop(k) for k in LEGACY_ENGINE_ARGS if k in overrides}
        if old:
            if spec is not None:
                raise InputError("DepthCompleter.from_pretrained: give spec or device / amp / backend, not both")
            spec = legacy_spec(old, "DepthCompleter.from_pretrained")
        resolved = resolve_weights(name_or_path, sha256=sha256, cache_dir=cache_dir, progress=progress)
        return cls(resolved.build(arch, overrides=overrides), spec, inplace=True)

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike[str], *args: object, **legacy: object) -> DepthCompleter:
        """Deprecated since 0.2 (goes in 0.3): :meth:`from_pretrained` under its older name."""
        import warnings

        warnings.warn(
            "DepthCompleter.from_checkpoint is deprecated since 0.2 and goes in 0.3: use "
            "DepthCompleter.from_pretrained(path, spec=EngineSpec(...))",
            DeprecationWarning,
            stacklevel=2,
        )
        old = dict(zip(("device", "amp", "backend"), args, strict=False)) | legacy
        spec = legacy_spec(old, "DepthCompleter.from_checkpoint") if old else None
        return cls.from_pretrained(path, spec, progress=False)

    @property
    def outputs(self) -> frozenset[str] | None:
        """The fields of :class:`~semattnet.models.outputs.DepthCompletionOutput` the caller reads (None: all, the
        default): ``refined_depth`` for the final depth, ``uncertainty`` for the uncertainty (computed only when
        among them, and :attr:`compute_uncertainty`). The engines compiled for one size (``openvino``) compute only
        what these need (:func:`~semattnet.models.uncertainty.outputs_to_compute`; the other fields are then None);
        the ``torch`` engine computes them all.

        Raises:
            InputError: an unknown field name.
        """
        return self._outputs

    @outputs.setter
    def outputs(self, names: Collection[str] | None) -> None:
        self._outputs = None if names is None else check_output_names(names, "outputs")

    def engine(self, size: tuple[int, int] | None = None) -> InferenceEngine:
        """The engine for padded inputs of ``size`` and the :attr:`outputs` (built on first use; one for all sizes
        and outputs with ``torch``)."""
        fixed = self.spec.entry.fixed_size
        key = (size, outputs_to_compute(self._outputs)) if fixed else (None, None)
        if key not in self._engines:
            self._engines[key] = optimize_for_inference(
                self._source,
                backend=self.backend,
                size=key[0],
                precision=self.spec.engine_precision,
                device=self.device,
                inplace=self._inplace and not fixed,
                calibration=self.calibration,
                outputs=key[1],
            )
        return self._engines[key]

    @contextmanager
    def timing(self, hook: StageClock) -> Iterator[tuple[str, ...]]:
        """While active, the stages the engine runs inside a call (the ``torch`` engine's ``propagation``) run
        inside ``hook(stage)``; gives those stages (empty: this engine does not split its call)."""
        engine = None if self.spec.entry.fixed_size else self.engine(None)
        if engine is None or not engine.inner_stages:
            yield ()
            return
        engine.on_stage = hook
        try:
            yield engine.inner_stages
        finally:
            engine.on_stage = None

    @property
    def model(self) -> nn.Module:
        """The engine for any size (``torch`` backend), called like the model: what evaluation loops run."""
        return self._source if self.spec.entry.fixed_size else self.engine(None)

    def run(self, rgb: torch.Tensor, semantic: torch.Tensor | None, sparse: torch.Tensor) -> DepthCompletionOutput:
        """Batched tensors (B, C, H, W) of any H, W -> outputs at the same size, with their ``uncertainty``
        (:func:`semattnet.models.uncertainty.depth_uncertainty`: from the outputs every engine returns and
        ``sparse``, so the same for every engine up to float rounding; not with ``compute_uncertainty = False``, nor
        when :attr:`outputs` leaves it out).

        Raises:
            InputError: NaN / infinite, negative or too large sparse depth (checked here too, as exported
                backends skip the model's own checks).
        """
        check_sparse_depth(sparse)
        want_uncertainty = self.compute_uncertainty and (self._outputs is None or "uncertainty" in self._outputs)
        if self.generalist is not None:  # scale, colour and anchor around the network (models.generalist)
            with torch.inference_mode():
                sem = None if semantic is None else semantic.to(self.device)
                inputs = self.generalist.prepare(rgb.to(self.device), sparse.to(self.device), sem)
                out = self._run_network(inputs.rgb, inputs.semantic, inputs.depth)
                return self.generalist.finish(out.map(lambda t: t.to(self.device)), inputs, want_uncertainty)
        out = self._run_network(rgb, semantic, sparse)
        if not want_uncertainty:
            return out
        with torch.inference_mode():
            return with_uncertainty(out, sparse)

    def _run_network(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None, sparse: torch.Tensor
    ) -> DepthCompletionOutput:
        """The engine on padded inputs, its outputs cropped back to the inputs' size."""
        rgb_p, pad = pad_to_multiple(rgb)
        sparse_p, _ = pad_to_multiple(sparse)
        sem_p = pad_to_multiple(semantic)[0] if semantic is not None else None
        with (
            torch.inference_mode(),
            torch.autocast(self.device.type, dtype=self.amp or torch.float32, enabled=self.amp is not None),
        ):
            engine = self.engine((int(rgb_p.shape[-2]), int(rgb_p.shape[-1])))
            semantic_in = None if sem_p is None else sem_p.to(self.device)
            out: DepthCompletionOutput = engine(
                rgb=rgb_p.to(self.device), semantic=semantic_in, sparse=sparse_p.to(self.device)
            )
        return out.map(lambda t: crop_padding(t.float(), pad))

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        """Complete one frame: ``rgb`` (H, W, 3) 0..255, ``sparse`` (H, W) metres (0 = none),
        ``semantic`` (H, W, 3) colour-coded 0..255 (required by three-branch models)."""
        return self.complete_batch([(rgb, sparse, semantic)])[0]

    def check_frame(
        self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None
    ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """The input checks of a call (shapes, colour ranges, sparse depth with points), then the frame as
        (1, C, H, W) float32 tensors ``(rgb, semantic, sparse)``.

        Raises:
            InputError: the frame's own fault, naming what is wrong.
        """
        rgb, sparse = np.asarray(rgb), np.asarray(sparse)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise InputError(f"rgb must be (H, W, 3), got {rgb.shape}")
        if sparse.shape != rgb.shape[:2]:
            raise InputError(f"sparse must be (H, W) = {rgb.shape[:2]}, got {sparse.shape}")
        if semantic is None and self.needs_semantic:
            raise InputError("semantic: this model needs a semantic map (see `semattnet segment` or the README)")
        if semantic is not None and np.asarray(semantic).shape != rgb.shape:
            raise InputError(f"semantic must be {rgb.shape}, got {np.asarray(semantic).shape}")

        for name, a in (("rgb", rgb), ("semantic", semantic)):
            _check_colour_range(name, a)
        depth_in = torch.from_numpy(np.ascontiguousarray(sparse, dtype=np.float32))
        check_sparse_depth(depth_in)
        check_has_points(depth_in)

        def image(a: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1)[None]

        return image(rgb), None if semantic is None else image(semantic), depth_in[None, None]

    def complete_batch(self, frames: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray | None]]) -> list[Completion]:
        """Frames ``(rgb, sparse, semantic)`` of one size in one engine call, each checked as a call checks it
        (:meth:`check_frame`): one :class:`Completion` per frame, in order (equal to one call per frame up to
        float rounding)."""
        inputs = [self.check_frame(*f) for f in frames]
        if len({x[0].shape for x in inputs}) > 1 or len({x[1] is None for x in inputs}) > 1:
            raise InputError("complete_batch: a batch's frames must have one size and all (or none) a semantic map")
        semantic = [x[1] for x in inputs if x[1] is not None]
        out = self.run(
            _batch([x[0] for x in inputs]), _batch(semantic) if semantic else None, _batch([x[2] for x in inputs])
        )
        out = out.map(lambda t: t.cpu())
        return [Completion(out.depth[i, 0].numpy(), out.map(partial(_item, i=i))) for i in range(len(inputs))]

    def stream(
        self,
        source: FrameSource,
        semantic: SemanticMaps | None = None,
        *,
        timer: StageTimes | None = None,
        prefetch: int = 2,
        names: Sequence[str] | None = None,
    ) -> Iterator[tuple[Frame, Completion]]:
        """``(frame, completion)`` for every frame of ``source`` (a :class:`~semattnet.data.frames.FrameSource`;
        ``names``: some of its frames), in order, while the next ``prefetch`` frames are read, decoded, projected
        and segmented in a background thread (bounded: at most ``prefetch`` frames ahead).

        ``semantic``: a :class:`~.semantic.SemanticMaps` (default: the fallback map when the model
        needs one). ``timer``: a :class:`~semattnet.inference.timing.StageTimes` that gets every stage's time
        (``timer.table()`` afterwards). The loop is :func:`semattnet.inference.feed.completions`, the one that
        ``complete_frames`` writes from."""
        from semattnet.inference.feed import completions
        from semattnet.inference.semantic import SemanticMaps

        maps = (semantic if semantic is not None else SemanticMaps()).bind(self)
        yield from completions(source, self, names, maps, timer, prefetch)


def load_completer(
    weights: str | os.PathLike[str], spec: EngineSpec | None = None, *, progress: bool = True
) -> DepthCompleter:
    """The completer of ``weights`` (a released name, a file or folder, a URL:
    :func:`semattnet.weights.from_pretrained`) on the engine ``spec`` says (default: ``torch`` on the best
    device), folded in place: the one builder every command (and a live node) runs its model through."""
    return DepthCompleter(from_pretrained(weights, map_location="cpu", progress=progress), spec, inplace=True)
