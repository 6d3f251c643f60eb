"""Inference engines: the model made ready to run, by the fastest backend this machine has.

>>> import torch, semattnet
>>> from semattnet.inference.backends import optimize_for_inference
>>> net = semattnet.build_model("semattnet", width=0.125)
>>> engine = optimize_for_inference(net, backend="torch")
>>> x = {"rgb": torch.zeros(1, 3, 64, 64), "semantic": torch.zeros(1, 3, 64, 64), "sparse": torch.zeros(1, 1, 64, 64)}
>>> engine(**x).refined_depth.shape
torch.Size([1, 1, 64, 64])

Backends, one entry each in the engine table (:mod:`~semattnet.inference.backends.registry`; see the README's
"Benchmarks" for measurements and which to use on which CPU):

* ``torch``: eager PyTorch on a BatchNorm-folded copy, with the fused C++ propagation kernel on
  the CPU; any size, any device.
* ``openvino``: the model exported to ONNX once, converted to OpenVINO IR and compiled for the
  CPU at one input size; cached on disk by weights, size and versions (``pip install
  'semattnet[openvino]'``).
* ``onnxruntime``: the same ONNX export run by ONNX Runtime (``pip install 'semattnet[onnx]'``).
* ``tensorrt``: CUDA only; the network compiled by Torch-TensorRT at one size, the propagation
  in PyTorch (``pip install 'semattnet[tensorrt]'``; a one-line error without it).
* ``auto``: ``openvino`` for CPU inference at a known size when it is installed, else ``torch``;
  ``precision="int8"`` (asked for explicitly, never a default) is OpenVINO's NNCF-quantised engine.
"""

from __future__ import annotations

import os
from collections.abc import Collection

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.inference.backends._base import InferenceEngine, LogFn, output_from_arrays
from semattnet.inference.backends.calibration import DEFAULT_CALIBRATION_FRAMES, CalibrationFrames
from semattnet.inference.backends.registry import (
    EngineEntry,
    EngineRequest,
    choose_backend,
    engine_entries,
    get_engine,
    precisions,
    register_engine,
    unregister_engine,
)
from semattnet.inference.backends.spec import EngineSpec
from semattnet.models.outputs import check_output_names

__all__ = [
    "EngineEntry",
    "EngineRequest",
    "EngineSpec",
    "InferenceEngine",
    "available_backends",
    "choose_backend",
    "engine_entries",
    "get_engine",
    "needs_semantic",
    "optimize_for_inference",
    "output_from_arrays",
    "precisions",
    "register_engine",
    "unregister_engine",
]


def needs_semantic(model: object) -> bool:
    """Whether ``model`` takes a semantic map: a completer (or engine) says so in its ``needs_semantic``
    attribute; a model does unless its config has two branches (a model without a config counts as
    three-branch). The one home of this rule."""
    if hasattr(model, "needs_semantic"):
        return bool(model.needs_semantic)
    if not isinstance(model, nn.Module):
        return False
    config = getattr(model, "config", None)
    return config is None or getattr(config, "branches", 3) == 3


def available_backends() -> list[str]:
    """The engines whose packages are installed (``torch`` always), in the table's order."""
    return [name for name, entry in engine_entries().items() if entry.installed()]


def optimize_for_inference(
    model: nn.Module,
    *,
    backend: str = "auto",
    size: tuple[int, int] | None = None,
    precision: str = "f32",
    device: torch.device | str = "cpu",
    cache_dir: str | os.PathLike[str] | None = None,
    inplace: bool = False,
    log: LogFn | None = None,
    calibration: CalibrationFrames = None,
    calibration_frames: int = DEFAULT_CALIBRATION_FRAMES,
    compile_propagation: bool | None = None,
    outputs: Collection[str] | None = None,
) -> InferenceEngine:
    """``model`` ready to run: ``engine(rgb=, semantic=, sparse=)`` -> ``DepthCompletionOutput``.

    The model itself is not changed (folding happens on a copy; ``inplace=True`` folds ``model``
    itself and saves the copy's memory); the weights stay exactly in the authors' layout.
    ``size`` (H, W; multiples of 32) is required by the engines compiled for one size (``openvino``,
    ``onnxruntime``, ``tensorrt``; cached on disk under ``cache_dir``, default ``$SEMATTNET_CACHE``).
    ``backend``, ``precision`` and ``device`` are checked and chosen by :meth:`EngineSpec.resolve`.
    ``precision="bf16"`` is faster only on CPUs with native bfloat16 (on CUDA use ``torch`` with
    autocast); ``f32`` outputs match the eager model within 1e-4 relative.
    ``precision="int8"`` (OpenVINO; ``auto`` then means OpenVINO) quantises the network (not the
    propagation) with NNCF on ``calibration`` frames: a FrameSource, Frames or a folder, else
    synthetic scenes (:mod:`~semattnet.inference.backends.calibration`; at most
    ``calibration_frames`` of them), cached on disk per weights, size and calibration.
    ``precision="fp16"``: CUDA (``torch`` autocast, ``tensorrt``). ``compile_propagation``
    (``torch``; default: on CUDA): the propagation through ``torch.compile``
    (:mod:`~semattnet.inference.backends.compiled_propagation`). ``outputs``: the fields of
    :class:`~semattnet.models.outputs.DepthCompletionOutput` you read (None: all, the default); ``openvino``
    then compiles only the part of the graph they need (the others are None), the other engines return all of
    them (``refined_depth`` stands for the final depth: ``fused_depth`` for a model without refinement).
    """
    spec = EngineSpec(backend, precision, device).resolve(fixed_size=size is not None)
    entry = spec.entry
    if entry.fixed_size and size is None:
        raise InputError(f"size: the {entry.name} backend compiles for one input size: pass size=(H, W)")
    request = EngineRequest(
        None if size is None else (int(size[0]), int(size[1])),
        spec.precision or "f32",
        torch.device(spec.device),
        needs_semantic(model),
        cache_dir,
        log,
        inplace,
        calibration,
        calibration_frames,
        compile_propagation,
        None if outputs is None else check_output_names(outputs, "outputs"),
    )
    return entry.build(model.eval(), request)
