"""Markdown and self-contained HTML reports: a KITTI metrics table plus figures.

Images are linked by paths relative to the report, so the folder can be moved or zipped whole.
The HTML page flags any image that fails to load (red caption) and records the count in
``<body data-images="loaded/total">`` once the page has loaded.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path
from typing import TypedDict

from semattnet._utils.atomic import atomic_path

__all__ = ["HeldOutCounts", "ReportSetup", "metrics_rows", "write_report"]


class HeldOutCounts(TypedDict):
    """The held-out scenes: how many, and how many of them with a shadow band."""

    frames: int
    shadowed: int


class _ReportFacts(TypedDict):
    device: str
    torch_threads: int
    seconds: float
    held_out: HeldOutCounts


class ReportSetup(_ReportFacts, total=False):
    """The facts listed under the report's table; ``steps``: method -> stage -> steps, ``verdicts``: sentences."""

    steps: dict[str, dict[str, int]]
    verdicts: list[str]


#: (metric key, column title) of the table; RMSE per group, the rest over all frames.
_COLUMNS = (
    ("all", "rmse_mm", "RMSE [mm]"),
    ("shadowed", "rmse_mm", "RMSE shadowed [mm]"),
    ("unshadowed", "rmse_mm", "RMSE unshadowed [mm]"),
    ("all", "mae_mm", "MAE [mm]"),
    ("all", "irmse_per_km", "iRMSE [1/km]"),
    ("all", "imae_per_km", "iMAE [1/km]"),
)


def metrics_rows(
    metrics: dict[str, dict[str, dict[str, float]]], labels: dict[str, str]
) -> tuple[list[str], list[list[str]]]:
    """Header and rows (method label, then the columns) of the metrics table."""
    header = ["Method"] + [title for _, _, title in _COLUMNS]
    rows = []
    for method, groups in metrics.items():
        cells = [labels.get(method, method)]
        for group, key, _ in _COLUMNS:
            value = groups.get(group, {}).get(key)
            cells.append("-" if value is None else f"{value:.1f}" if key.endswith("mm") else f"{value:.2f}")
        rows.append(cells)
    return header, rows


def _write(path: Path, text: str) -> None:
    with atomic_path(path, suffix=path.suffix) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_report(
    out_dir: str | Path,
    metrics: dict[str, dict[str, dict[str, float]]],
    labels: dict[str, str],
    figures: Sequence[tuple[str, str]],
    setup: ReportSetup,
    title: str = "SemAttNet demo on synthetic scenes",
    links: Sequence[tuple[str, str]] = (),
) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.html`` into ``out_dir``.

    Args:
        metrics: method -> group -> KITTI metrics (as :meth:`~semattnet.evaluation.metrics.KittiMetrics.compute`
            returns).
        labels: method -> display name.
        figures: (caption, image path relative to ``out_dir``).
        setup: facts shown under the table (device, timings, settings, ...).
        links: (text, path relative to ``out_dir``) listed above the table, e.g. the viewer.
    """
    out = Path(out_dir)
    header, rows = metrics_rows(metrics, labels)
    facts = _facts(labels, setup)
    md_path, html_path = out / "report.md", out / "report.html"
    _write(md_path, _markdown(title, header, rows, facts, figures, links))
    _write(html_path, _html(title, header, rows, facts, figures, links))
    return md_path, html_path


def _facts(labels: dict[str, str], setup: ReportSetup) -> list[str]:
    """The sentences listed under the table: held-out scenes, device and time, steps, how metrics are computed."""
    facts = [
        f"Held-out scenes: {setup['held_out']['frames']} ({setup['held_out']['shadowed']} with a shadow band), "
        "never seen in training.",
        f"Device: {setup['device']} ({setup['torch_threads']} threads); whole run {setup['seconds'] / 60:.1f} min.",
    ]
    facts += [
        f"{labels.get(k, k)}: {v['backbone']} backbone steps, then {v['full']} full-model steps."
        for k, v in setup.get("steps", {}).items()
    ]
    facts += list(setup.get("verdicts", []))
    facts.append(
        "Metrics are the KITTI benchmark's (means over images; holes in a prediction filled as the devkit "
        "does, so the sparse input is scored after that filling)."
    )
    return facts


def _markdown(
    title: str,
    header: list[str],
    rows: list[list[str]],
    facts: list[str],
    figures: Sequence[tuple[str, str]],
    links: Sequence[tuple[str, str]] = (),
) -> str:
    """The Markdown report: title, links, metrics table, facts, then each figure with its caption."""
    md = [f"# {title}", ""] + [f"- [{text}]({href})" for text, href in links] + ([""] if links else [])
    md += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    md += ["| " + " | ".join(r) + " |" for r in rows]
    md += [""] + [f"- {f}" for f in facts] + [""]
    for caption, src in figures:
        md += [f"![{caption}]({src})", "", f"*{caption}*", ""]
    return "\n".join(md)


def _html_table(header: list[str], rows: list[list[str]]) -> str:
    """The metrics table's ``<tr>`` rows, the method names as row headers (escaped)."""
    esc = html.escape
    table = "<tr>" + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr>\n"
    for r in rows:
        table += "<tr>" + f"<th>{esc(r[0])}</th>" + "".join(f"<td>{esc(c)}</td>" for c in r[1:]) + "</tr>\n"
    return table


def _html(
    title: str,
    header: list[str],
    rows: list[list[str]],
    facts: list[str],
    figures: Sequence[tuple[str, str]],
    links: Sequence[tuple[str, str]] = (),
) -> str:
    """The self-contained HTML page; its script flags images that fail to load and counts those that do."""
    esc = html.escape
    figs = "\n".join(
        f'<figure><img src="{esc(src)}" alt="{esc(caption)}"><figcaption>{esc(caption)}</figcaption></figure>'
        for caption, src in figures
    )
    nav = "".join(f'<li><a href="{esc(href)}">{esc(text)}</a></li>' for text, href in links)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
th, td {{ border: 1px solid #ccc; padding: 4px 10px; text-align: right; }}
tr th:first-child {{ text-align: left; }}
figure {{ margin: 2em 0; }} img {{ max-width: 100%; border: 1px solid #ddd; }}
figcaption {{ color: #555; font-size: 0.9em; }} .broken {{ color: #b00; font-weight: bold; }}
</style></head>
<body data-images="pending">
<h1>{esc(title)}</h1>
{f'<ul class="links">{nav}</ul>' if nav else ""}
<table>
{_html_table(header, rows)}</table>
<ul>{"".join(f"<li>{esc(f)}</li>" for f in facts)}</ul>
{figs}
<script>
window.addEventListener("load", () => {{
  const imgs = Array.from(document.images);
  const ok = imgs.filter((i) => i.complete && i.naturalWidth > 0);
  imgs.filter((i) => !ok.includes(i)).forEach((i) => {{
    const note = document.createElement("p");
    note.className = "broken";
    note.textContent = "missing image: " + i.getAttribute("src");
    i.after(note);
  }});
  document.body.dataset.images = ok.length + "/" + imgs.length;
}});
</script>
</body></html>
"""
