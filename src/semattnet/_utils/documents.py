"""Bounded parsing of the JSON and YAML documents semattnet reads from files.

One home for the bounds on structured text from a file (a ``config.json``, the JSON in a
safetensors header's metadata, a rig file): at most :data:`MAX_DOCUMENT_BYTES` bytes, nested at
most :data:`MAX_NESTING` levels deep, and for YAML no aliases (a 400-byte alias bomb
expands to gigabytes). Every refusal is one line naming the file (``where``) and what is wrong.
"""

from __future__ import annotations

import json
import os
from typing import TypeAlias

from semattnet._errors import DataError, SemAttNetError
from semattnet._utils.bounds import regular_file
from semattnet._utils.extras import install_hint, optional

__all__ = ["JSON", "MAX_DOCUMENT_BYTES", "MAX_NESTING", "JSONObject", "loads_json", "loads_yaml", "read_document"]

#: Largest JSON / YAML document read from a file (bytes).
MAX_DOCUMENT_BYTES = 1 << 20
#: Deepest nesting of lists / objects in such a document.
MAX_NESTING = 32

#: A parsed JSON (or safe-loaded YAML) value: the one type for documents read from files.
JSON: TypeAlias = bool | int | float | str | list["JSON"] | dict[str, "JSON"] | None
#: A parsed JSON object (what a ``config.json`` or a record must be at its top).
JSONObject: TypeAlias = dict[str, JSON]


def _depth(doc: JSON) -> int:
    """Nesting depth of lists and dicts in ``doc`` (iterative: no recursion limit)."""
    deepest, stack = 0, [(doc, 1)]
    while stack:
        obj, level = stack.pop()
        if isinstance(obj, dict | list):
            deepest = max(deepest, level)
            stack.extend((v, level + 1) for v in (obj.values() if isinstance(obj, dict) else obj))
    return deepest


def _check_size(text: str | bytes, where: str, error: type[SemAttNetError], max_bytes: int) -> None:
    n = len(text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text)
    if n > max_bytes:
        raise error(f"{where}: document of {n} bytes is larger than the {max_bytes} accepted")


def loads_json(
    text: str | bytes,
    where: str | os.PathLike[str],
    *,
    error: type[SemAttNetError] = DataError,
    max_bytes: int = MAX_DOCUMENT_BYTES,
    max_depth: int = MAX_NESTING,
) -> JSON:
    """``json.loads(text)`` refusing documents over ``max_bytes`` or nested deeper than ``max_depth``.

    Raises:
        error: not JSON, too large or too deeply nested (the message names ``where``).
    """
    _check_size(text, str(where), error, max_bytes)
    try:
        doc = json.loads(text)
    except RecursionError:
        raise error(f"{where}: JSON nested deeper than {max_depth} levels") from None
    except (ValueError, UnicodeDecodeError) as exc:  # json.JSONDecodeError is a ValueError
        raise error(f"{where}: not valid JSON: {str(exc).splitlines()[0]}") from None
    if _depth(doc) > max_depth:
        raise error(f"{where}: JSON nested deeper than {max_depth} levels")
    return doc


def loads_yaml(
    text: str,
    where: str | os.PathLike[str],
    *,
    error: type[SemAttNetError] = DataError,
    max_bytes: int = MAX_DOCUMENT_BYTES,
    max_depth: int = MAX_NESTING,
) -> JSON:
    """``yaml.safe_load(text)`` refusing aliases, documents over ``max_bytes`` and
    nesting deeper than ``max_depth`` (checked on the event stream, before anything is built).

    Raises:
        error: PyYAML missing, not YAML, an alias, too large or too deeply nested.
    """
    _check_size(text, str(where), error, max_bytes)
    yaml = optional("yaml")
    if yaml is None:
        raise error(f"{where}: reading YAML needs PyYAML ({install_hint('yaml')}); or use JSON")
    try:
        level = 0
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.AliasEvent):
                raise error(f"{where}: YAML aliases (*{event.anchor}) are not accepted")
            level += isinstance(event, yaml.CollectionStartEvent) - isinstance(event, yaml.CollectionEndEvent)
            if level > max_depth:
                raise error(f"{where}: YAML nested deeper than {max_depth} levels")
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise error(f"{where}: not valid YAML: {str(exc).splitlines()[0]}") from None


def read_document(
    path: str | os.PathLike[str], *, error: type[SemAttNetError] = DataError, max_bytes: int = MAX_DOCUMENT_BYTES
) -> JSON:
    """Parse the JSON (or, for ``.yaml`` / ``.yml``, YAML) file ``path`` under the bounds above;
    its size is checked before it is read."""
    path = regular_file(path, "document", error)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise error(f"{path}: document of {size} bytes is larger than the {max_bytes} accepted")
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        return loads_yaml(text, path, error=error, max_bytes=max_bytes)
    return loads_json(text, path, error=error, max_bytes=max_bytes)
