"""What ``semattnet weights`` shows and resolves: the registry as a table, ``--weights`` as a local file."""

from __future__ import annotations

from pathlib import Path

from semattnet._errors import InputError
from semattnet.weights.pretrained import get_weights, list_pretrained

__all__ = ["WeightsSpecError", "resolve_weights_file", "weights_table"]

_UNKNOWN_SHA = "unknown (pinned on first download)"


class WeightsSpecError(InputError):
    """A ``--weights`` value that names no file, folder, URL or registered weights."""


def _licence(text: str) -> str:
    """The licence's first clause (the registry holds a paragraph)."""
    head = text.split(":", 1)[0].split(";", 1)[0].strip()
    return head if len(head) <= 40 else head[:39] + "…"


def _rmse(metrics: dict) -> str:
    parts = [f"{split} {m['rmse_mm']:g} mm" for split, m in metrics.items() if "rmse_mm" in m]
    return ", ".join(parts) or "-"


def _weights_rows() -> list[tuple[str, ...]]:
    from semattnet.weights.download import read_pins

    pins = read_pins()
    rows: list[tuple[str, ...]] = []
    for name in list_pretrained():
        w = get_weights(name)
        pinned = pins.get(f"{w.name}/{w.file_name}", {}).get("sha256")
        sha = w.sha256 or (f"{pinned} (pinned)" if pinned else _UNKNOWN_SHA)
        params = f"{w.num_params / 1e6:.1f} M" if w.num_params else "?"
        rows.append((w.name, w.arch, params, w.trained_on or "-", w.file_name, sha, _licence(w.license),
                     _rmse(dict(w.paper_metrics))))  # fmt: skip
    return rows


def _table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = ["  ".join(c.ljust(wd) for c, wd in zip(r, widths, strict=True)).rstrip() for r in [header, *rows]]
    return "\n".join([lines[0], "  ".join("-" * wd for wd in widths), *lines[1:]])


def resolve_weights_file(spec: str, progress: bool = True) -> Path:
    """A local weights file for ``--weights NAME|PATH|URL``: registry names and URLs go through the cache.

    A folder (``save_pretrained`` output, ``hf://`` repository) gives its ``model.safetensors``.
    """
    from semattnet.weights.download import fetch
    from semattnet.weights.hub import WEIGHTS_NAME, packed_file

    path = Path(spec).expanduser()
    if spec in list_pretrained() and get_weights(spec).format == "packed":
        path = packed_file(get_weights(spec))
    elif spec in list_pretrained():
        path = fetch(get_weights(spec), progress=progress)
    elif "://" in spec:
        path = fetch(spec, progress=progress)
    elif not path.exists():
        known = ", ".join(list_pretrained())
        raise WeightsSpecError(f"--weights {spec!r}: not a file, a URL or a registered name ({known})")
    if path.is_dir():
        path = path / WEIGHTS_NAME
        if not path.is_file():
            raise WeightsSpecError(f"--weights {spec}: folder without {WEIGHTS_NAME}")
    return path


def weights_table() -> str:
    """``semattnet weights list``: name, architecture, parameters, training data, file, sha256 (or pin),
    licence, reported RMSE (the paper's for the authors' weights, the own validation scenes' for the demo's)."""
    header = ("name", "arch", "params", "trained on", "file", "sha256", "licence", "reported RMSE")
    return _table(header, _weights_rows())
