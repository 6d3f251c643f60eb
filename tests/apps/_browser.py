"""Playwright on Debian's Chromium for the viewer tests: skip without them, fail in CI (SEMATTNET_REQUIRE_BROWSER=1)."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def _unavailable(why: str) -> None:
    if os.environ.get("SEMATTNET_REQUIRE_BROWSER"):
        pytest.fail(f"{why}: run scripts/setup-browser.sh and pip install -e '.[dev]'")
    pytest.skip(why)


def chromium_path() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    _unavailable("no Chromium (scripts/setup-browser.sh installs it)")
    return ""


@contextmanager
def open_page(path: Path, viewport: tuple[int, int] = (1300, 1200)) -> Iterator[tuple[Any, list[str]]]:
    """A Playwright page showing ``path`` and the list of its console errors and page errors."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _unavailable("no playwright (pip install playwright; no browser download needed)")
    executable = chromium_path()
    errors: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": viewport[0], "height": viewport[1]})
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(path.resolve().as_uri())
            yield page, errors
        finally:
            browser.close()


def wait_ready(page: Any, index: int = 0) -> None:
    page.wait_for_selector(f"body[data-ready='{index}']", timeout=30000)


def hover_pixel(page: Any, u: int, v: int) -> dict[str, float | None]:
    """Hover over pixel (u, v) of the viewer's image; the readout as key -> metres (None: no depth)."""
    scale = float(page.get_attribute("#view", "data-scale"))
    page.hover("#view", position={"x": (u + 0.5) * scale, "y": (v + 0.5) * scale})
    page.wait_for_function(
        f"() => document.getElementById('pixel').dataset.u === '{u}' "
        f"&& document.getElementById('pixel').dataset.v === '{v}'"
    )
    js = "rows => rows.map(r => [r.dataset.key, r.querySelector('td').dataset.value])"
    cells = page.eval_on_selector_all("#readout tr", js)
    return {key: (float(value) if value else None) for key, value in cells}
