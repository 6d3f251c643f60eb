"""The authors' own model code, imported at run time from a checkout the user supplies (``--authors-src``).

Nothing of the authors' repository (https://github.com/danishnazir/SemAttNet) is part of this one: the
benchmarks take the folder of a clone, e.g. ``git clone https://github.com/danishnazir/SemAttNet
/tmp/SemAttNet`` and ``--authors-src /tmp/SemAttNet``, and import its ``model.py`` (which imports
``basic.py`` and ``attention.py`` beside it) from there, unchanged:

* **isolated import**: the folder is put first on ``sys.path`` only while ``model`` is imported, and
  their top-level names (``model``, ``basic``, ``attention``) are taken out of ``sys.modules`` afterwards
  (any of ours restored), so nothing else in the process sees them;
* **their arguments**: ``A_CSPN_plus_plus(args)`` reads ``args.network_model`` and ``args.dilation_rate``
  (the released full model: ``"sem_att"`` and 2, :data:`AUTHORS_ARGS`; their ``main.py`` also sets
  ``val_h``/``val_w`` and ``cpu``, given here too);
* **CPU shim**: while their model is built and run without CUDA, ``torch.Tensor.cuda`` and
  ``torch.nn.Module.cuda`` are no-ops (:func:`cpu_shim`), for checkouts that move tensors to the GPU
  unconditionally. The released ``model.py`` / ``basic.py`` / ``attention.py`` make no such call, so the
  shim changes nothing there; it is what would be needed, and all that is done, never an edit of their files;
* **outputs**: their forward takes ``{"rgb", "d", "semantic"}`` and returns an 8-tuple; :class:`AuthorsModel`
  calls it like ours (``rgb=, semantic=, sparse=``) and names the tuple's entries as
  :class:`~semattnet.models.outputs.DepthCompletionOutput` does (the mapping of
  ``tests/reference/test_authors_equivalence.py``), so our loss and parity checks apply unchanged.

The state-dict names of our ``build_model("semattnet")`` are theirs, so one set of weights fills both:
:func:`fill_weights` writes, entry by entry, values drawn from a generator seeded by the entry's name (the
shape of the reference rule in ``tests/reference/fixtures/README.md``, drawn with torch's generator), so a
process that builds only one of the two models still gets the same weights.
"""

from __future__ import annotations

import contextlib
import importlib
import math
import sys
import zlib
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType, SimpleNamespace
from typing import Any

import torch
from torch import nn

from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["AUTHORS_ARGS", "AuthorsModel", "build_authors_model", "cpu_shim", "fill_weights", "load_authors_module"]

#: The attributes their ``A_CSPN_plus_plus(args)`` (and their main.py) reads, for the released full model.
AUTHORS_ARGS = {"network_model": "sem_att", "dilation_rate": 2, "val_h": 352, "val_w": 1216, "cpu": True}
#: Their forward's 8 outputs, in order, by our names.
OUTPUT_NAMES = (
    "color_conf",
    "semantic_conf",
    "guided_conf",
    "color_depth",
    "semantic_depth",
    "guided_depth",
    "refined_s2_depth",
    "refined_depth",
)
_THEIR_MODULES = ("model", "basic", "attention")


def load_authors_module(src: str | Path) -> ModuleType:
    """Their ``model.py`` from the checkout ``src``, imported without leaving their names in ``sys.modules``."""
    folder = Path(src).resolve()
    if not (folder / "model.py").is_file():
        raise SystemExit(f"--authors-src {src}: no model.py there (expected a clone of danishnazir/SemAttNet)")
    saved = {k: sys.modules.pop(k) for k in _THEIR_MODULES if k in sys.modules}
    sys.path.insert(0, str(folder))
    try:
        module = importlib.import_module("model")
    finally:
        sys.path.remove(str(folder))
        for k in _THEIR_MODULES:
            sys.modules.pop(k, None)
        sys.modules.update(saved)
    if not hasattr(module, "A_CSPN_plus_plus"):
        raise SystemExit(f"--authors-src {src}: model.py defines no A_CSPN_plus_plus")
    return module


@contextlib.contextmanager
def cpu_shim() -> Iterator[None]:
    """Without CUDA: ``Tensor.cuda`` and ``Module.cuda`` return their object unchanged while active."""
    if torch.cuda.is_available():
        yield
        return
    tensor_cuda, module_cuda = torch.Tensor.cuda, nn.Module.cuda
    torch.Tensor.cuda = lambda self, *a, **k: self  # type: ignore[method-assign]
    nn.Module.cuda = lambda self, *a, **k: self  # type: ignore[method-assign]
    try:
        yield
    finally:
        torch.Tensor.cuda, nn.Module.cuda = tensor_cuda, module_cuda  # type: ignore[method-assign]


class AuthorsModel(nn.Module):
    """Their ``A_CSPN_plus_plus`` called like ours: ``model(rgb=, semantic=, sparse=)`` -> ``DepthCompletionOutput``."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net

    def forward(self, rgb: torch.Tensor, semantic: torch.Tensor, sparse: torch.Tensor) -> DepthCompletionOutput:
        with cpu_shim():
            out = self.net({"rgb": rgb, "d": sparse, "semantic": semantic})
        named: dict[str, Any] = dict(zip(OUTPUT_NAMES, out, strict=True))
        # their result has no separate fused depth: the refined_s2 entry is their (aliased) coarse depth
        return DepthCompletionOutput(fused_depth=named["refined_s2_depth"], **named)


def build_authors_model(src: str | Path, size: tuple[int, int] = (352, 1216), seed: int = 0) -> AuthorsModel:
    """Their full model from the checkout ``src``, filled by :func:`fill_weights` (``seed``), on the CPU."""
    module = load_authors_module(src)
    args = SimpleNamespace(**(AUTHORS_ARGS | {"val_h": size[0], "val_w": size[1]}))
    with cpu_shim():
        net = module.A_CSPN_plus_plus(args)
    return AuthorsModel(fill_weights(net, seed))


def fill_weights(model: nn.Module, seed: int = 0) -> nn.Module:
    """Every state-dict entry of ``model`` from a generator seeded by its name (in place, no large temporaries):
    BatchNorm scales and running variances ``0.75 + 0.5 u``, running means and biases ``0.05 (2u - 1)``,
    convolution weights ``(2u - 1) / sqrt(fan_in)``, ``num_batches_tracked`` 0."""
    with torch.no_grad():
        for name, t in model.state_dict().items():
            leaf = name.rsplit(".", 1)[-1]
            if leaf == "num_batches_tracked":
                t.zero_()
                continue
            t.uniform_(0.0, 1.0, generator=torch.Generator().manual_seed(zlib.crc32(name.encode()) + seed))
            if leaf == "running_var" or (leaf == "weight" and t.dim() == 1):
                t.mul_(0.5).add_(0.75)
            elif leaf in ("running_mean", "bias"):
                t.mul_(0.1).sub_(0.05)
            else:
                t.mul_(2.0).sub_(1.0).div_(math.sqrt(t.shape[1] * math.prod(t.shape[2:])))
    return model
