"""The built site in headless Chromium: home page and an API page without console errors; search works."""

from __future__ import annotations

import functools
import http.server
import os
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.apps._browser import ARGS, chromium_path


def _unavailable(why: str) -> None:
    if os.environ.get("SEMATTNET_REQUIRE_BROWSER"):
        pytest.fail(f"{why}: pip install -e '.[dev]'")
    pytest.skip(why)


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture(scope="module")
def served(built_site: Path) -> Iterator[str]:
    """The site on a local HTTP server (the search index is fetched by a web worker; no network)."""
    handler = functools.partial(_QuietHandler, directory=str(built_site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


@pytest.mark.slow  # builds the whole site first (40 s on two busy cores); CI's make docs builds it strictly
def test_home_and_api_page_render_and_search_finds_a_term(served: str) -> None:
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _unavailable("no playwright (pip install playwright; no browser download needed)")
    executable = chromium_path()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1300, "height": 1000})
            errors: list[str] = []
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            outside: list[str] = []
            page.on("request", lambda r: outside.append(r.url) if not r.url.startswith(served) else None)
            for url in (served, served + "reference/api/models/"):
                page.goto(url)
                page.wait_for_load_state("networkidle")
            assert "SemAttNetConfig" in page.content()
            page.goto(served)
            page.wait_for_load_state("networkidle")
            page.locator("input.md-search__input").press_sequentially("aliasing", delay=50)
            page.wait_for_selector(".md-search-result__item", timeout=20000)
            assert page.locator(".md-search-result__item").count() > 0
            assert not errors, errors
            assert not outside, f"requests outside the site: {outside}"
        finally:
            browser.close()
