"""Old import paths of the synthetic scenes, deprecated since 0.2 and gone in 0.3, each with a ``DeprecationWarning``
naming the new home.

The synthetic world moved out of ``semattnet.data`` to :mod:`semattnet.synthetic`, a layer above it (it reads and
writes KITTI trees with ``data``). ``data`` may not import it back, so the old paths are answered from here, the
package's top layer, which may import both: ``import semattnet.data.synthetic`` (and its modules:
``semattnet.data.synthetic.drive``, ...) through an import hook, and the four names ``semattnet.data`` exported
(``make_frame``, ``write_synthetic_kitti``, ``SyntheticFrame``, ``CITYSCAPES_PALETTE``) through its module
``__getattr__``. :mod:`semattnet` imports this module, so the old paths work whatever is imported first.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from types import ModuleType

from semattnet import data, synthetic

__all__ = ["MOVED_MODULES", "MOVED_NAMES", "REMOVED_IN"]

#: The release that drops the old paths.
REMOVED_IN = "0.3"
#: Old module path -> new one (its modules follow: ``old.x`` -> ``new.x``).
MOVED_MODULES = {"semattnet.data.synthetic": "semattnet.synthetic"}
#: Names ``semattnet.data`` exported -> the module they live in now.
MOVED_NAMES = {
    "CITYSCAPES_PALETTE": synthetic.__name__,
    "SyntheticFrame": synthetic.__name__,
    "make_frame": synthetic.__name__,
    "write_synthetic_kitti": synthetic.__name__,
}


def _warn(old: str, new: str) -> None:
    """A ``DeprecationWarning`` attributed to the code that named ``old``: two frames up, as ``warnings`` skips the
    import machinery's own frames (``exec_module`` / ``_moved_name`` -> the caller)."""
    warnings.warn(
        f"{old} is deprecated since 0.2 and goes in {REMOVED_IN}: use {new}", DeprecationWarning, stacklevel=3
    )


def _new_name(name: str) -> str | None:
    for old, new in MOVED_MODULES.items():
        if name == old or name.startswith(old + "."):
            return new + name[len(old) :]
    return None


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old module path last (after every other finder has not), as a module holding the new one's names."""

    def find_spec(
        self, fullname: str, path: object = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = _new_name(fullname)
        if new is None or importlib.util.find_spec(new) is None:
            return None
        is_package = importlib.util.find_spec(new).submodule_search_locations is not None  # type: ignore[union-attr]
        return importlib.util.spec_from_loader(fullname, self, is_package=is_package)

    def exec_module(self, module: ModuleType) -> None:
        new = _new_name(module.__name__)
        assert new is not None  # find_spec answered for this name only
        _warn(module.__name__, new)
        real = importlib.import_module(new)
        module.__dict__.update({k: v for k, v in vars(real).items() if not k.startswith("__")})
        module.__all__ = list(getattr(real, "__all__", ()))  # type: ignore[attr-defined]
        module.__doc__ = f"Deprecated alias of {new} (until {REMOVED_IN})."


def _moved_name(name: str) -> object:
    """``semattnet.data``'s module ``__getattr__``: the names that moved, with a warning."""
    if name not in MOVED_NAMES:
        raise AttributeError(f"module 'semattnet.data' has no attribute {name!r}")
    if "importlib" not in sys._getframe(1).f_code.co_filename:  # from-import asks hasattr first: warn once
        _warn(f"semattnet.data.{name}", f"{MOVED_NAMES[name]}.{name}")
    return getattr(sys.modules[MOVED_NAMES[name]], name)


if not any(isinstance(f, _MovedModules) for f in sys.meta_path):
    sys.meta_path.append(_MovedModules())
vars(data)["__getattr__"] = _moved_name
