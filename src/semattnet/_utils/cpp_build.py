"""C++ CPU kernels compiled on first use with :func:`torch.utils.cpp_extension.load_inline`, shared by the fused
propagation (:mod:`semattnet.models.propagation.cpu_kernel`) and the classical completion
(:mod:`semattnet.models.anchor_kernel`).

A build needs a C++ compiler (``CXX``, else ``c++``) and the ``ninja`` package; it is cached in torch's extensions
folder and said on stderr with the time it took. Without them, or when the build fails, one line on stderr says
what is missing and the caller uses its PyTorch path. ``SEMATTNET_NO_CPP=1`` disables every kernel. A build lock
that torch left behind when a build was killed (older than :data:`STALE_LOCK_S`) is removed instead of waited on
forever.
"""

from __future__ import annotations

import os
import shutil
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

__all__ = ["DISABLE_ENV", "STALE_LOCK_S", "InlineKernel"]

#: Set (to anything non-empty) to disable every compiled kernel: the PyTorch paths are used.
DISABLE_ENV = "SEMATTNET_NO_CPP"
#: A build lock older than this (seconds) was left by a build that was killed (a build takes about a minute).
STALE_LOCK_S = 600.0
_CFLAGS = ("-O3", "-march=native", "-fno-math-errno")


def _say(text: str) -> None:
    """One line on stderr."""
    print(f"semattnet: {text}", file=sys.stderr, flush=True)


def missing_tools() -> str | None:
    """What a build lacks (a C++ compiler, ninja), or None."""
    from torch.utils.cpp_extension import is_ninja_available

    compiler = os.environ.get("CXX") or "c++"
    if shutil.which(compiler) is None:
        return f"no C++ compiler ({compiler} not found; install one or set CXX)"
    if not is_ninja_available():
        return "no ninja (pip install ninja)"
    return None


class InlineKernel:
    """One C++ extension, built (or loaded from torch's cache) on the first :meth:`load`, once per process.

    Args:
        name: the extension's name (its build folder); a new version for new sources.
        source: the C++ source.
        functions: the functions bound to Python.
        what: what it is, for the messages ("the fused CPU propagation kernel" -> "building the ...").
        fallback: what is used without it, for the message saying it is unavailable.
        cflags: extra compiler flags (the default: optimised for this CPU).
    """

    def __init__(
        self, name: str, source: str, functions: Sequence[str], what: str, fallback: str, cflags: Sequence[str] = ()
    ) -> None:
        self.name, self.source, self.functions = name, source, list(functions)
        self.what, self.fallback, self.cflags = what, fallback, [*_CFLAGS, *cflags]
        self.stale_lock_s = STALE_LOCK_S
        self.module: object | None = None
        self.failed: str | None = None
        self._lock = threading.Lock()

    def build_dir(self) -> Path:
        """torch's build folder of the extension (``TORCH_EXTENSIONS_DIR`` or ``~/.cache/torch_extensions/...``)."""
        from torch.utils.cpp_extension import _get_build_directory

        return Path(_get_build_directory(self.name, False))

    def _clear_stale_lock(self, build: Path) -> None:
        """Wait for another process's build at most until its lock is ``stale_lock_s`` old; an older lock is a
        killed build's and is removed (torch itself would wait on it forever)."""
        lock = build / "lock"
        while True:
            try:
                age = time.time() - lock.stat().st_mtime
            except FileNotFoundError:
                return
            if age > self.stale_lock_s:
                _say(f"removing {lock}, left by a build that was killed {age / 60:.0f} min ago")
                lock.unlink(missing_ok=True)
                return
            time.sleep(min(1.0, self.stale_lock_s - age + 0.01))

    def _build(self, build: Path) -> object:
        """The compiled module: built (and said so, with the time taken) when not cached yet."""
        from torch.utils.cpp_extension import load_inline

        self._clear_stale_lock(build)
        fresh = not (build / f"{self.name}.so").is_file()
        if fresh:
            _say(f"building {self.what} (once; about a minute) ...")
        start = time.perf_counter()
        module = load_inline(
            name=self.name, cpp_sources=[self.source], functions=self.functions, extra_cflags=self.cflags, verbose=False
        )
        if fresh:
            _say(f"built {self.what} in {time.perf_counter() - start:.1f} s ({build})")
        return module

    def load(self) -> object | None:
        """The compiled module, or None (and why in :attr:`failed`, said once on stderr)."""
        if self.module is not None or self.failed is not None:
            return self.module
        with self._lock:
            if self.module is not None or self.failed is not None:
                return self.module
            if os.environ.get(DISABLE_ENV):
                self.failed = f"disabled by {DISABLE_ENV}"
                return None
            try:
                build = self.build_dir()
                self.failed = None if (build / f"{self.name}.so").is_file() else missing_tools()
                if self.failed is None:
                    self.module = self._build(build)
            except Exception as err:  # a failed build, ...: fall back to PyTorch
                self.failed = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            if self.failed is not None:
                _say(f"{self.what} is unavailable ({self.failed}); using {self.fallback}")
            return self.module

    def available(self) -> bool:
        """Whether the compiled kernel can be used (builds it on the first call)."""
        return self.load() is not None

    def require(self) -> object:
        """The compiled module.

        Raises:
            RuntimeError: it is unavailable (the reason).
        """
        module = self.load()
        if module is None:
            raise RuntimeError(f"{self.what} is unavailable: {self.failed}")
        return module
