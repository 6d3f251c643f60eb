"""Fill the registries: import every module of the package, so that an entry registered anywhere (the robot
sources and sinks register from :mod:`semattnet.robotics`) is listed and runs through its suite."""

from __future__ import annotations

import importlib
import pkgutil

import semattnet


def import_all() -> None:
    """Import every ``semattnet`` module but the ``__main__`` ones (none imports an optional package)."""
    for module in pkgutil.walk_packages(semattnet.__path__, "semattnet."):
        if not module.name.endswith("__main__"):
            importlib.import_module(module.name)
