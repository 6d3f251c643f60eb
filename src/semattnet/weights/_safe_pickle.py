"""A pickle module for ``torch.load`` that never runs code named by the checkpoint.

``torch.load(path, pickle_module=safe_pickle_module(), weights_only=False)`` resolves every
global the pickle names through :meth:`Unpickler.find_class`:

* tensors, parameters, dtypes, ``OrderedDict``, ``argparse.Namespace`` and NumPy scalars/arrays
  resolve to the real objects (they only rebuild data);
* names that can run code (``os.system``, ``builtins.eval``, ``subprocess.*``, ...) are refused
  with :class:`UnsafeCheckpointError`;
* other names from ``torch``, NumPy and similar libraries are refused too (``torch.load`` named
  by a pickle is code, not data), except what ``torch.load(weights_only=True)`` allows by default;
* any other class (e.g. the authors' ``metrics.Result``) becomes an inert stand-in that only
  records the data it is built from, so its fields stay readable;
* state (BUILD, SETITEMS, ...) is applied only to objects the pickle created, never to a class,
  function or module it named, so no load changes the calling process.

:func:`describe_torch_refusal` turns a refusal of ``torch.load(weights_only=True)`` into one line
without torch's advice to retry with ``weights_only=False``.

:func:`resolve_global` is the policy; :mod:`semattnet.weights.checkpoint` applies it to the globals
it finds (statically) in a pickle and hands the answers to ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import _compat_pickle
import pickle
import pickletools
import re
import struct
import sys
import types
from collections.abc import Callable
from typing import IO, Any

import torch

from semattnet._errors import SemAttNetError
from semattnet._utils.extras import optional

__all__ = [
    "InertObject",
    "Unpickler",
    "UnsafeCheckpointError",
    "describe_torch_refusal",
    "resolve_global",
    "safe_pickle_module",
]


class UnsafeCheckpointError(SemAttNetError, pickle.UnpicklingError):
    """The checkpoint references a callable that could execute code."""


class InertObject:
    """Stand-in for a class named by a checkpoint that we refuse to import.

    Constructor arguments are kept in ``_args``; pickled state becomes attributes.
    """

    _pickled_name = "?"

    def __new__(cls, *args: object, **kwargs: object) -> InertObject:
        return object.__new__(cls)

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.__dict__["_args"] = args
        if kwargs:
            self.__dict__["_kwargs"] = kwargs

    def __setstate__(self, state: object) -> None:
        if isinstance(state, tuple) and len(state) == 2 and isinstance(state[0], dict | type(None)):
            state = {**(state[0] or {}), **(state[1] or {})}
        if isinstance(state, dict):
            self.__dict__.update({str(k): v for k, v in state.items()})
        else:
            self.__dict__["_state"] = state

    def __repr__(self) -> str:
        shown = {k: v for k, v in self.__dict__.items() if not isinstance(v, torch.Tensor)}
        return f"<inert {self._pickled_name} {shown}>"


_SAFE: dict[tuple[str, str], object] = {
    ("collections", "OrderedDict"): __import__("collections").OrderedDict,
    ("builtins", "set"): set,
    ("builtins", "frozenset"): frozenset,
    ("builtins", "slice"): slice,
    ("builtins", "complex"): complex,
    ("builtins", "bytearray"): bytearray,
    ("argparse", "Namespace"): __import__("argparse").Namespace,
    ("_codecs", "encode"): __import__("codecs").encode,  # how protocol-2 pickles store bytes (NumPy arrays)
    ("torch", "Size"): torch.Size,
    ("torch", "device"): torch.device,
    ("torch._utils", "_rebuild_tensor"): torch._utils._rebuild_tensor,
    ("torch._utils", "_rebuild_tensor_v2"): torch._utils._rebuild_tensor_v2,
    ("torch._utils", "_rebuild_parameter"): torch._utils._rebuild_parameter,
    ("torch._utils", "_rebuild_parameter_with_state"): torch._utils._rebuild_parameter_with_state,
    ("torch.nn.parameter", "Parameter"): torch.nn.Parameter,
}
for _name in ("_rebuild_tensor_v3",):
    if hasattr(torch._utils, _name):
        _SAFE[("torch._utils", _name)] = getattr(torch._utils, _name)

_NUMPY_SAFE = {"_reconstruct", "scalar", "ndarray", "dtype"}
_NUMPY_MODULES = {"numpy", "numpy.core.multiarray", "numpy._core.multiarray"}

# Modules whose members can run code, touch files or the network, or import other code.
_DANGEROUS_ROOTS = {
    "os",
    "posix",
    "nt",
    "subprocess",
    "sys",
    "builtins",
    "__builtin__",
    "shutil",
    "socket",
    "importlib",
    "runpy",
    "pickle",
    "_pickle",
    "marshal",
    "ctypes",
    "code",
    "codeop",
    "pty",
    "webbrowser",
    "multiprocessing",
    "asyncio",
    "tempfile",
    "pathlib",
    "types",
    "functools",
    "operator",
    "platform",
    "signal",
    "threading",
    "urllib",
    "http",
    "ftplib",
    "smtplib",
    "requests",
    "pdb",
    "timeit",
    "trace",
    "inspect",
    "gc",
    "io",
    "shelve",
    "dbm",
    "sqlite3",
    "zipimport",
}


def _resolve_numpy(module: str, name: str) -> object:
    import numpy as np

    if name == "ndarray":
        return np.ndarray
    if name == "dtype":
        return np.dtype
    for mod in ("numpy._core.multiarray", "numpy.core.multiarray"):
        found = getattr(optional(mod), name, None)
        if found is not None:
            return found
    raise pickle.UnpicklingError(f"cannot resolve {module}.{name}")


# Libraries whose functions are code, not data: a name from them that is not allowed above is refused
# rather than neutralised (e.g. ``torch.load`` or ``torch.jit.load`` named by a pickle).
_LIBRARY_ROOTS = {"torch", "numpy", "safetensors", "semattnet", "torchvision", "scipy", "PIL", "cv2", "yaml"}
_CODE_NAMES = {
    "eval",
    "exec",
    "system",
    "__import__",
    "popen",
    "compile",
    "getattr",
    "setattr",
    "open",
    "load",
    "loads",
    "apply",
}


def _torch_weights_only_allowed() -> dict[str, object]:
    """The globals ``torch.load(weights_only=True)`` allows by default (tensor rebuilding, dtypes, ...)."""
    allowed = getattr(optional("torch._weights_only_unpickler"), "_get_allowed_globals", None)
    return dict(allowed()) if allowed is not None else {}  # {} on a torch without it


def resolve_global(module: str, name: str, sink: set[str] | None = None) -> object:
    """The object a pickle may get for the global ``module.name``, under this module's policy.

    Data-rebuilding names resolve to the real objects; names that can run code raise
    :class:`UnsafeCheckpointError`; any other class becomes an inert stand-in (its name is added to
    ``sink``). Python 2 names (``commands.call``, ``__builtin__.eval``) are judged by the Python 3
    names the unpickler would import (``subprocess.call``, ``builtins.eval``).
    """
    if (module, name) in _compat_pickle.NAME_MAPPING:
        module, name = _compat_pickle.NAME_MAPPING[(module, name)]
    elif module in _compat_pickle.IMPORT_MAPPING:
        module = _compat_pickle.IMPORT_MAPPING[module]
    if (module, name) in _SAFE:
        return _SAFE[(module, name)]
    if module == "torch" and isinstance(getattr(torch, name, None), torch.dtype):
        return getattr(torch, name)
    if module in _NUMPY_MODULES and name in _NUMPY_SAFE:
        return _resolve_numpy(module, name)
    root = module.split(".")[0]
    if root in _DANGEROUS_ROOTS or name.split(".")[-1] in _CODE_NAMES:
        raise UnsafeCheckpointError(f"refusing to load: the pickle calls {module}.{name}, which could run code")
    allowed = _torch_weights_only_allowed().get(f"{module}.{name}")
    if allowed is not None:
        return allowed
    if root in _LIBRARY_ROOTS or not name.isidentifier():
        raise UnsafeCheckpointError(f"refusing to load: the pickle calls {module}.{name}, which is code, not data")
    qualname = f"{module}.{name}"
    if sink is not None:
        sink.add(qualname)
    return type(name, (InertObject,), {"_pickled_name": qualname, "__module__": "semattnet.inert"})


def _is_shared(obj: object, named: dict[int, object]) -> bool:
    """Whether ``obj`` is an object of the calling process rather than one the pickle created: a
    global the pickle named (a class, function, module), or a built-in NumPy dtype singleton."""
    if id(obj) in named or isinstance(obj, type | types.ModuleType | types.FunctionType | types.BuiltinFunctionType):
        return True
    np = sys.modules.get("numpy")
    return np is not None and isinstance(obj, np.dtype) and bool(obj.isbuiltin)


def _guarded(op: str, base: Any, target: Any) -> Any:
    """``base`` (a ``pickle._Unpickler`` opcode handler) refusing to change a shared object."""

    def load(self: Unpickler) -> None:
        try:
            obj = target(self)
        except IndexError:
            raise pickle.UnpicklingError(f"malformed pickle: {op} with an empty stack") from None
        if _is_shared(obj, self.named):
            what = getattr(obj, "__qualname__", None) or type(obj).__qualname__
            raise UnsafeCheckpointError(
                f"refusing to load: the pickle's {op} would change {what}, an object of this process, not a new "
                "instance the pickle created"
            )
        base(self)

    return load


_BASE = pickle._Unpickler  # the Python implementation: its opcode table can be guarded
# The handlers receive this module's Unpickler (typeshed types the table with the C pickle.Unpickler).
_DISPATCH: dict[int, Callable[[Any], None]] = dict(_BASE.dispatch)
_OPCODE_NAME = {ord(o.code): o.name for o in pickletools.opcodes}
for _op, _target in (
    (pickle.BUILD, lambda u: u.stack[-2]),
    (pickle.SETITEM, lambda u: u.stack[-3]),
    (pickle.APPEND, lambda u: u.stack[-2]),
    (pickle.SETITEMS, lambda u: u.metastack[-1][-1]),
    (pickle.APPENDS, lambda u: u.metastack[-1][-1]),
    (pickle.ADDITEMS, lambda u: u.metastack[-1][-1]),
):
    _DISPATCH[_op[0]] = _guarded(_OPCODE_NAME[_op[0]], _DISPATCH[_op[0]], _target)


def _refuse_extension(self: Unpickler) -> None:
    raise UnsafeCheckpointError("refusing to load: the pickle uses the copyreg extension registry (EXT opcodes)")


for _op in (pickle.EXT1, pickle.EXT2, pickle.EXT4):
    _DISPATCH[_op[0]] = _refuse_extension


class Unpickler(_BASE):
    """Unpickler with the allow / refuse / neutralise policy of :func:`resolve_global`.

    Allow-listed classes stay inert: BUILD, SETITEM(S), APPEND(S) and ADDITEMS only change objects
    the pickle itself created, never a class, function or module it named (``argparse.Namespace``
    stays as it is), and the copyreg extension registry is not consulted.
    """

    #: Receives the qualified names replaced by inert stand-ins (see safe_pickle_module).
    sink: set[str] | None = None
    dispatch = _DISPATCH

    def __init__(self, file: IO[bytes], **kwargs: Any) -> None:
        super().__init__(file, **kwargs)
        self.named: dict[int, object] = {}  # id -> every object find_class gave out (kept alive)

    def find_class(self, module: str, name: str) -> object:
        obj = resolve_global(module, name, self.sink)
        self.named[id(obj)] = obj
        return obj

    def load(self) -> object:
        try:
            return super().load()
        except (pickle.UnpicklingError, SemAttNetError):
            raise
        except (IndexError, KeyError, TypeError, AttributeError, EOFError, ValueError, struct.error) as exc:
            raise pickle.UnpicklingError(f"malformed pickle ({type(exc).__name__}: {exc})") from None


_TORCH_ADVICE = re.compile(r"weights.only|safe_globals|trust|re-run|please", re.IGNORECASE)
_ADVICE_CLAUSE = re.compile(r",? or (?:classes|types) allowlisted\s+via `add_safe_globals`")
_UNSUPPORTED_GLOBAL = re.compile(r"Unsupported global: GLOBAL ([\w.]+)")
_UNSUPPORTED_OPCODE = re.compile(r"Unsupported operand (\d+)")


def describe_torch_refusal(exc: BaseException) -> str:
    """One line saying why ``torch.load(weights_only=True)`` refused a pickle, without torch's
    advice to retry with ``weights_only=False`` or to allow-list the global (never relayed)."""
    text = str(exc)
    if m := _UNSUPPORTED_GLOBAL.search(text):
        return f"refusing to load: the pickle names {m[1]}, which is not allowed in weights"
    if m := _UNSUPPORTED_OPCODE.search(text):
        op = _OPCODE_NAME.get(int(m[1]), m[1])
        return f"refusing to load: the pickle uses opcode {op}, which the restricted loader does not accept"
    detail = text.split("WeightsUnpickler error:", 1)[-1]
    line = _ADVICE_CLAUSE.sub("", next((ln.strip() for ln in detail.splitlines() if ln.strip()), ""))
    kept = [s for s in re.split(r"(?<=[.!?])\s+", line) if s and not _TORCH_ADVICE.search(s)]
    return "refusing to load: " + (kept[0] if kept else "the restricted loader refused the pickle")


def safe_pickle_module() -> tuple[types.SimpleNamespace, set[str]]:
    """A fresh pickle-module stand-in for ``torch.load`` and the set it fills with the names
    of the classes it neutralised."""
    neutralised: set[str] = set()
    unpickler = type("Unpickler", (Unpickler,), {"sink": neutralised})

    def load(file: IO[bytes], **kwargs: Any) -> object:
        return unpickler(file, **kwargs).load()

    return types.SimpleNamespace(__name__="semattnet_safe_pickle", Unpickler=unpickler, load=load), neutralised
