"""The real-time frontier's report: ``results.json`` and ``timing.json`` of ``benchmarks/frontier.py`` as a table,
the acceptance read from them and a plot, in ``docs/performance.md`` (between :data:`BEGIN` and :data:`END`) and
``docs/frontier.png``. Run by ``python benchmarks/frontier.py --out frontier-run --report``.

Nothing here imports torch: it reads the two files, so the report is remade in a second after the figures change.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path

BEGIN = "<!-- frontier:begin (written by benchmarks/frontier.py --report; edits between the markers are replaced) -->"
END = "<!-- frontier:end -->"
METRICS = ("rmse", "mae", "irmse", "imae")
#: Columns of the backends (timing.json's names) and their headers.
BACKENDS = {"torch-f32": "torch f32", "openvino-f32": "OV f32", "openvino-int8": "OV int8"}
#: Columns of a backend run with oneDNN's kernels capped at a lesser ISA (``frontier.py --isa-cap AVX2``): an
#: estimate of an AVX2-only CPU on this one, shown beside the others, never taken as a variant's fastest time.
CAPPED = {"openvino-f32-avx2": "OV f32, AVX2 kernels"}
COLUMNS = {**BACKENDS, **CAPPED}
BUDGET_MS = 100.0  # a 10 Hz LiDAR's period
RMSE_SLACK = 0.15  # within 15 % of the width-1/8 paper model's RMSE
INT8_SLACK = 0.01  # int8 metrics within 1 % of float32
MEMORY_NOTE = (
    "one forward in a fresh process, on the variant's fastest backend (Linux's VmHWM, reset through "
    "/proc/self/clear_refs once the engine is built)"
)
LABELS = {
    "classical": "classical completion",
    "paper_w1_8": "paper model, width 1/8",
    "paper_w1_4": "paper model, width 1/4",
}


def read_run(out: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``results.json`` and ``timing.json`` of a run folder; a missing or unreadable one is an InputError."""
    found = []
    for name in ("results.json", "timing.json"):
        path = out / name
        try:
            found.append(json.loads(path.read_text()))
        except (OSError, ValueError) as exc:
            why = "is missing" if not path.exists() else f"cannot be read ({type(exc).__name__})"
            raise InputError(f"{path} {why}: run the training half, then --time, before --report") from None
    return found[0], found[1]


def _ms(timing: Mapping[str, Any], key: str, backend: str) -> float | None:
    row = timing["rows"].get(f"{key}/{backend}")
    return None if row is None else float(row["ms"])


def best(timing: Mapping[str, Any], key: str) -> tuple[float, str] | None:
    """The fastest network + propagation of ``key``: (ms, backend), or None when it was not timed."""
    times = [(ms, b) for b in BACKENDS if (ms := _ms(timing, key, b)) is not None]
    return min(times) if times else None


def _spread(entry: Mapping[str, Any], metric: str) -> float:
    values = [float(s[metric]) for s in entry.get("per_seed", {}).values()]
    return (max(values) - min(values)) / 2 if len(values) > 1 else 0.0


def _score(entry: Mapping[str, Any], metric: str) -> str:
    """Mean of the seeds in the KITTI units (mm, 1/km), with half the seeds' range when there are several."""
    scale = 1000.0  # metres -> mm, 1/m -> 1/km
    mean = scale * float(entry["scores"][metric])
    spread = scale * _spread(entry, metric)
    digits = 0 if metric in ("rmse", "mae") else 1
    return f"{mean:.{digits}f} ± {spread:.{digits}f}" if spread else f"{mean:.{digits}f}"


def _cell(value: float | None, fmt: str = "{:.0f}") -> str:
    return "–" if value is None else fmt.format(value)


def table(results: Mapping[str, Any], timing: Mapping[str, Any]) -> str:
    """The frontier as a Markdown table: one row per variant (the classical completion first)."""
    res = results["results"]
    head = [
        "variant",
        "GMAC",
        "params",
        "RMSE [mm]",
        "MAE [mm]",
        "iRMSE [1/km]",
        "iMAE [1/km]",
        "AUSE (RMSE)",
        *(f"{h} [ms]" for h in COLUMNS.values()),
        "whole frame [ms]",
        "memory [MB]: growth / peak",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    for key, entry in res.items():
        counts = timing.get("models", {}).get(key, {})
        params = counts.get("params", entry.get("params"))
        ause = entry.get("uncertainty", {}).get("ause_rmse")
        fastest = best(timing, key)
        frame = timing.get("frames", {}).get(key, {}).get("frame_ms")
        row = {} if fastest is None else timing["rows"][f"{key}/{fastest[1]}"]
        measured = "peak_mb" in row and not math.isnan(row["peak_mb"])
        memory = f"{row['growth_mb']:.0f} / {row['peak_mb']:.0f}" if measured else "–"
        times = [_cell(_ms(timing, key, b)) for b in COLUMNS]
        if key == "classical":
            times = [_cell(timing.get("classical_ms")), *["–"] * (len(COLUMNS) - 1)]
        label = LABELS.get(key, f"`{key}`") + (" (convex kernel)" if entry.get("affinity") == "convex" else "")
        cells = [
            label,
            _cell(counts.get("gmac"), "{:.2f}"),
            "–" if params is None else f"{params / 1e6:.2f} M",
            *(_score(entry, m) for m in METRICS),
            _cell(ause, "{:.3f}"),
            *times,
            _cell(frame),
            memory,
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def cpu_line(timing: Mapping[str, Any]) -> str:
    """The CPU the times were taken on, its threads and ISA flags."""
    isa = ", ".join(timing.get("isa", [])) or "none of avx2/avx512/amx"
    return f"{timing['cpu']}, {timing['threads']} threads (ISA: {isa})"


def _pct(x: float) -> str:
    return f"{100 * x:+.1f} %"


def verdict(results: Mapping[str, Any], timing: Mapping[str, Any], key: str) -> str:
    """One variant against the acceptance: its fastest time and the budget, the classical completion on all four
    metrics, the width-1/8 paper model's RMSE, int8 against float32."""
    res = results["results"]
    scores, classical = res[key]["scores"], res["classical"]["scores"]
    fastest = best(timing, key)
    parts = [f"`{key}`:"]
    if fastest is None:
        parts.append("not timed;")
    else:
        ms, backend = fastest
        parts.append(
            f"{ms:.0f} ms network + propagation ({BACKENDS[backend]}), "
            f"{'within' if ms <= BUDGET_MS else 'over'} the {BUDGET_MS:.0f} ms budget;"
        )
        if (capped := _ms(timing, key, "openvino-f32-avx2")) is not None:
            parts.append(f"{capped:.0f} ms with AVX2 kernels only;")
    worse = [m for m in METRICS if scores[m] >= classical[m]]
    parts.append(
        "beats the classical completion on all four metrics;"
        if not worse
        else f"does not beat the classical completion on {', '.join(m.upper() for m in worse)};"
    )
    if "paper_w1_8" in res:
        rel = scores["rmse"] / res["paper_w1_8"]["scores"]["rmse"] - 1
        parts.append(
            f"RMSE {_pct(rel)} against the width-1/8 paper model "
            f"({'within' if rel <= RMSE_SLACK else 'outside'} {100 * RMSE_SLACK:.0f} %);"
        )
    int8 = timing.get("int8", {}).get(key)
    if int8 is None:
        parts.append("int8 accuracy not measured.")
    else:
        metric, change = max(int8["change"].items(), key=lambda kv: abs(kv[1]))
        ok = abs(change) <= INT8_SLACK
        parts.append(
            f"int8 {'within' if ok else 'outside'} {100 * INT8_SLACK:.0f} % of float32 (largest change "
            f"{_pct(change)}, {metric.upper()})."
        )
    return " ".join(parts)


def passes(results: Mapping[str, Any], timing: Mapping[str, Any], key: str) -> bool:
    """Whether ``key`` meets every acceptance item measured: network + propagation within the budget, better than
    the classical completion on all four metrics, RMSE within 15 % of the width-1/8 paper model's, and (where
    measured) int8 within 1 % of float32 on every metric."""
    res = results["results"]
    fastest = best(timing, key)
    scores = res[key]["scores"]
    int8 = timing.get("int8", {}).get(key)
    return (
        fastest is not None
        and fastest[0] <= BUDGET_MS
        and all(scores[m] < res["classical"]["scores"][m] for m in METRICS)
        and "paper_w1_8" in res
        and scores["rmse"] <= (1 + RMSE_SLACK) * res["paper_w1_8"]["scores"]["rmse"]
        and (int8 is None or all(abs(c) <= INT8_SLACK for c in int8["change"].values()))
    )


def summary(results: Mapping[str, Any], timing: Mapping[str, Any], keys: list[str]) -> str:
    """The acceptance in one line: the real-time variants that meet all of it, or that none does."""
    ok = [f"`{k}`" for k in keys if passes(results, timing, k)]
    if not ok:
        return "**Acceptance: no real-time variant meets all of it** (each one's reading below)."
    return (
        f"**Acceptance: met by {', '.join(ok)}**: within {BUDGET_MS:.0f} ms network + propagation, better than "
        f"the classical completion on all four metrics, RMSE within {100 * RMSE_SLACK:.0f} % of the width-1/8 "
        "paper model's (and int8 within 1 % of float32 where measured)."
    )


def bound(timing: Mapping[str, Any], keys: list[str]) -> str:
    """When no variant is within the budget: the fastest one's time and where it goes, measured (its whole frame's
    stages and the arithmetic rate it reached)."""
    timed = [(b[0], b[1], k) for k in keys if (b := best(timing, k)) is not None]
    if not timed:
        return "No real-time variant was timed."
    ms, backend, key = min(timed)
    if ms <= BUDGET_MS:
        return f"Fastest: `{key}`, {ms:.0f} ms ({BACKENDS[backend]}), within the {BUDGET_MS:.0f} ms budget."
    stages = timing.get("frames", {}).get(key, {}).get("stages_ms", {})
    where = ", ".join(f"{s} {v:.0f} ms" for s, v in stages.items())
    gmac = timing.get("models", {}).get(key, {}).get("gmac")
    rate = "" if gmac is None else f" It runs {gmac:.2f} GMAC at {2000 * gmac / ms:.0f} GFLOP/s"
    if gmac is not None and timing.get("conv_peak_gflops"):
        peak = timing["conv_peak_gflops"]
        rate += (
            f", {100 * 2000 * gmac / ms / peak:.0f} % of the float32 convolution peak measured here "
            f"({peak:.0f} GFLOP/s): bound by memory traffic and small operations, not by arithmetic"
        )
    rate += "." if rate else ""
    return (
        f"No real-time variant is within the {BUDGET_MS:.0f} ms budget: the best reached is {ms:.0f} ms "
        f"(`{key}`, {BACKENDS[backend]}); its whole frame: {where or 'not measured'}.{rate}"
    )


def plot(results: Mapping[str, Any], timing: Mapping[str, Any], path: Path) -> Path:
    """RMSE against network + propagation ms (log x): a point per variant (colour) and backend (marker; int8 at its
    int8 RMSE where measured), the classical completion as a line, the 100 ms budget dashed; the key beside the
    axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter

    res = results["results"]
    fig, ax = plt.subplots(figsize=(9, 4.2), dpi=90)
    markers = dict(zip(COLUMNS, "os^v", strict=True))
    variants = [k for k in res if k != "classical"]
    for i, key in enumerate(variants):
        for backend in COLUMNS:
            ms = _ms(timing, key, backend)
            int8 = timing.get("int8", {}).get(key) if backend.endswith("int8") else None
            rmse = (int8 or res[key])["scores"]["rmse"]  # the int8 points at the int8 scores where measured
            if ms is not None:
                ax.plot(ms, 1000 * rmse, markers[backend], color=f"C{i}")
    ax.axhline(1000 * res["classical"]["scores"]["rmse"], color="grey")
    ax.axvline(BUDGET_MS, color="grey", linestyle="--")
    # two keys beside the axes: colour = variant (and the two lines), marker = backend
    handles = [
        Line2D([], [], color=f"C{i}", marker="o", linestyle="", label=LABELS.get(k, k)) for i, k in enumerate(variants)
    ]
    handles += [
        Line2D([], [], color="grey", label=LABELS["classical"]),
        Line2D([], [], color="grey", linestyle="--", label=f"{BUDGET_MS:.0f} ms (10 Hz)"),
    ]
    handles += [Line2D([], [], color="black", marker=m, linestyle="", label=COLUMNS[b]) for b, m in markers.items()]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))
    ax.set_xlabel(f"network + propagation [ms], {timing['size'][0]}x{timing['size'][1]}")
    ax.set_ylabel("RMSE [mm], held-out scenes")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def section(results: Mapping[str, Any], timing: Mapping[str, Any], image: str) -> str:
    """What goes between the markers: the machine, the table, the acceptance read from the figures, the plot."""
    keys = [k for k in results["results"] if k not in LABELS]
    h, w = timing["size"]
    recipe = results.get("recipe", {})
    seeds = ", ".join(str(s) for s in results.get("seeds", []))
    frame_note = (
        "whole frame: the library's `predict --stream` loop on synthetic scenes as a folder input (read "
        "ahead, network, propagation, depth and colour PNGs written), median of the frames' summed stages, "
        "on the variant's fastest backend"
    )
    return "\n".join(
        [
            BEGIN,
            "",
            f"Measured on **{cpu_line(timing)}**, at {h}x{w}, batch 1, the median of {timing['repeats']} rounds in "
            f"turns; trained on {recipe.get('train_frames', '?')} synthetic scenes at "
            f"{'x'.join(map(str, recipe.get('size', [])))}, seeds {seeds} (scores: mean ± half the seeds' range on the "
            "held-out scenes).",
            "",
            table(results, timing),
            "",
            f"ms: network + propagation (median); {frame_note}; memory: the resident set during {MEMORY_NOTE}, its "
            "growth over the set before the forward and its high-water mark. The classical completion's time is in "
            "the torch f32 column; int8 scores are in timing.json.",
            "",
            summary(results, timing, keys),
            "",
            *(f"- {verdict(results, timing, k)}" for k in keys),
            "",
            bound(timing, keys),
            "",
            f"![RMSE against milliseconds, log scale]({image})",
            "",
            END,
        ]
    )


def replace_between(text: str, body: str, where: str) -> str:
    """``text`` with everything from :data:`BEGIN` to :data:`END` replaced by ``body`` (which holds both)."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise InputError(f"{where}: the frontier markers are missing ({BEGIN!r} ... {END!r})")
    return text[:start] + body + text[end + len(END) :]


def write_report(out: Path, doc: Path, image: Path) -> Path:
    """The run in ``out`` into ``doc`` (between the markers) and ``image``; returns ``doc``."""
    results, timing = read_run(out)
    text = replace_between(doc.read_text(), section(results, timing, image.name), str(doc))
    plot(results, timing, image)
    with atomic_path(doc) as tmp:
        tmp.write_text(text)
    return doc
