"""Inference engines: the model made ready to run, by the fastest backend this machine has.

>>> import torch, semattnet
>>> from semattnet.inference.backends import optimize_for_inference
>>> net = semattnet.build_model("semattnet", width=0.125)
>>> engine = optimize_for_inference(net, backend="torch")
>>> x = {"rgb": torch.zeros(1, 3, 64, 64), "semantic": torch.zeros(1, 3, 64, 64), "sparse": torch.zeros(1, 1, 64, 64)}
>>> engine(**x).refined_depth.shape
torch.Size([1, 1, 64, 64])

Backends (see the README's "Benchmarks" for measurements and which to use on which CPU):

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

import importlib.util
import os

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.inference.backends._base import InferenceEngine, LogFn, output_from_arrays
from semattnet.inference.backends.calibration import DEFAULT_CALIBRATION_FRAMES, CalibrationFrames
from semattnet.inference.backends.torch_engine import TorchEngine

__all__ = ["BACKENDS", "BACKEND_PRECISIONS", "PRECISIONS", "InferenceEngine", "available_backends", "choose_backend",
           "needs_semantic", "optimize_for_inference", "output_from_arrays"]  # fmt: skip

BACKENDS: tuple[str, ...] = ("torch", "openvino", "onnxruntime", "tensorrt")
PRECISIONS: tuple[str, ...] = ("f32", "bf16", "fp16", "int8")
_PACKAGES = {"openvino": "openvino", "onnxruntime": "onnxruntime", "tensorrt": "torch_tensorrt"}
#: The precisions each backend runs (``int8``: NNCF post-training quantisation, OpenVINO only).
BACKEND_PRECISIONS = {"torch": ("f32", "bf16", "fp16"), "openvino": ("f32", "bf16", "int8"),
                      "onnxruntime": ("f32",), "tensorrt": ("f32", "fp16")}  # fmt: skip


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
    """The backends whose packages are installed (``torch`` always)."""
    return [b for b in BACKENDS if b == "torch" or importlib.util.find_spec(_PACKAGES[b]) is not None]


def choose_backend(
    device: torch.device | str = "cpu", size: tuple[int, int] | None = None, precision: str = "f32"
) -> str:
    """What ``backend="auto"`` picks: OpenVINO for CPU inference at a fixed size if installed, else torch;
    ``precision="int8"`` always OpenVINO (the only int8 engine)."""
    if precision == "int8":
        return "openvino"
    cpu = torch.device(device).type == "cpu"
    if cpu and size is not None and precision in BACKEND_PRECISIONS["openvino"] and "openvino" in available_backends():
        return "openvino"
    return "torch"


def _check(backend: str, precision: str, size: tuple[int, int] | None) -> None:
    if backend not in (*BACKENDS, "auto"):
        raise InputError(f"unknown backend {backend!r}; choose one of auto, {', '.join(BACKENDS)}")
    if precision not in PRECISIONS:
        raise InputError(f"unknown precision {precision!r}; choose one of {', '.join(PRECISIONS)}")
    if backend in ("openvino", "onnxruntime") and size is None:
        raise InputError(f"the {backend} backend compiles for one input size: pass size=(H, W)")
    if backend == "onnxruntime" and precision != "f32":
        raise InputError("the onnxruntime backend runs float32 only")
    _check_precision(backend, precision, size)


def _check_precision(backend: str, precision: str, size: tuple[int, int] | None) -> None:
    """The int8 / fp16 / TensorRT rules (:data:`BACKEND_PRECISIONS`)."""
    if backend != "auto" and precision not in BACKEND_PRECISIONS[backend]:
        raise InputError(f"precision: the {backend} backend runs {', '.join(BACKEND_PRECISIONS[backend])}, "
                         f"got {precision!r}")  # fmt: skip
    if (precision == "int8" or backend == "tensorrt") and size is None:
        raise InputError(f"size: {backend} {precision} compiles for one input size: pass size=(H, W)")


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
) -> InferenceEngine:
    """``model`` ready to run: ``engine(rgb=, semantic=, sparse=)`` -> ``DepthCompletionOutput``.

    The model itself is not changed (folding happens on a copy; ``inplace=True`` folds ``model``
    itself and saves the copy's memory); the weights stay exactly in the authors' layout.
    ``size`` (H, W; multiples of 32) is required by ``openvino``/``onnxruntime``, which compile for
    one size (cached on disk under ``cache_dir``, default ``$SEMATTNET_CACHE``).
    ``precision="bf16"`` is faster only on CPUs with native bfloat16 (on CUDA use ``torch`` with
    autocast); ``f32`` outputs match the eager model within 1e-4 relative.
    ``precision="int8"`` (OpenVINO; ``auto`` then means OpenVINO) quantises the network (not the
    propagation) with NNCF on ``calibration`` frames: a FrameSource, Frames or a folder, else
    synthetic scenes (:mod:`~semattnet.inference.backends.calibration`; at most
    ``calibration_frames`` of them), cached on disk per weights, size and calibration.
    ``precision="fp16"``: CUDA (``torch`` autocast, ``tensorrt``). ``compile_propagation``
    (``torch``; default: on CUDA): the propagation through ``torch.compile``
    (:mod:`~semattnet.inference.backends.compiled_propagation`).
    """
    _check(backend, precision, size)
    backend = choose_backend(device, size, precision) if backend == "auto" else backend
    semantic = needs_semantic(model)
    model = model.eval()
    if backend == "torch":
        return TorchEngine(model.to(device), precision, semantic, inplace, compile_propagation)
    if backend == "onnxruntime":
        from semattnet.inference.backends.onnxruntime_engine import OnnxRuntimeEngine

        return OnnxRuntimeEngine(model.cpu(), tuple(size), semantic, cache_dir, log)  # type: ignore[arg-type]
    if backend == "tensorrt":
        from semattnet.inference.backends.tensorrt_engine import TensorRTEngine

        return TensorRTEngine(model, tuple(size), semantic, precision, torch.device(device))  # type: ignore[arg-type]
    from semattnet.inference.backends.openvino_engine import OpenVinoEngine

    return OpenVinoEngine(model.cpu(), tuple(size), semantic, precision, cache_dir, log,  # type: ignore[arg-type]
                          calibration=calibration, calibration_frames=calibration_frames)  # fmt: skip
