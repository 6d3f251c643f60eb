"""ROS names the way ``rclcpp`` resolves them: ``~/x`` (private), ``x`` (relative), ``/x`` (absolute)."""

from __future__ import annotations

import re

from semattnet._errors import InputError

__all__ = ["check_namespace", "resolve_name"]

_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def check_namespace(namespace: str, option: str = "--namespace") -> str:
    """``namespace`` as an absolute name without a trailing ``/`` (``""`` for the root); a one-line error else."""
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    if ns and not all(_TOKEN.fullmatch(part) for part in ns[1:].split("/")):
        raise InputError(f"{option} {namespace!r}: expected names of letters, digits and _ joined by / (e.g. /robot1)")
    return ns


def resolve_name(name: str, namespace: str = "", node: str = "semattnet", what: str = "topic") -> str:
    """The absolute topic of ``name`` for node ``node`` in ``namespace`` (``what`` names it in the error).

    >>> resolve_name("~/output/depth_image", "/robot1"), resolve_name("camera/image_raw", "/robot1")
    ('/robot1/semattnet/output/depth_image', '/robot1/camera/image_raw')
    """
    ns = check_namespace(namespace)
    full = name
    if name.startswith("~"):
        full = f"{ns}/{node}{name[1:]}"
    elif not name.startswith("/"):
        full = f"{ns}/{name}"
    parts = full.split("/")[1:]
    if not parts or not all(_TOKEN.fullmatch(p) for p in parts):
        raise InputError(f"{what} {name!r}: expected names of letters, digits and _ joined by / (e.g. /camera/image)")
    return full
