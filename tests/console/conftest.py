"""Fixtures for the console's browser tests: Debian's Chromium driven by Playwright's
Python API (``executable_path``; never ``playwright install``, which downloads a browser).

Without Chromium or Playwright the browser tests are skipped, except in CI (``CI=true``),
where a missing browser is a failure: the README's test block installs both.
"""

from __future__ import annotations

import asyncio
import os
import shutil
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest

from tests.waiting import eventually

#: Flags that work on the project's machines (headless, no sandbox as root, nothing that
#: calls home) plus software WebGL (SwiftShader) for the 3-D view.
CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync",
                  "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]


def chromium_path() -> str | None:
    for candidate in (os.environ.get("AFA_CHROMIUM"), "/usr/bin/chromium",
                      shutil.which("chromium"), shutil.which("chromium-browser")):
        if candidate and Path(candidate).exists():
            return candidate
    return None


def _missing(reason: str) -> None:
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(f"{reason} (CI=true: the browser tests must run; see the README's test "
                    "block)")
    pytest.skip(reason)


@pytest.fixture
def artifacts(tmp_path: Path, request: Any) -> Path:
    """Where screenshots and figures go: $AFA_TEST_ARTIFACTS/<test> if set, else the
    test's tmp dir."""
    root = os.environ.get("AFA_TEST_ARTIFACTS")
    folder = Path(root) / request.node.name if root else tmp_path / "artifacts"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@pytest.fixture
async def browser() -> AsyncIterator[Any]:
    path = chromium_path()
    if path is None:
        _missing("no Chromium (apt-get install -y chromium)")
    try:
        from playwright.async_api import async_playwright
    except ImportError:
        _missing("Playwright is not installed (pip install -e '.[test]')")
    async with async_playwright() as playwright:
        # Playwright gives the browser a fresh, empty profile of its own each launch
        launched = await playwright.chromium.launch(executable_path=path, headless=True,
                                                    args=CHROMIUM_FLAGS)
        try:
            yield launched
        finally:
            await launched.close()


class ConsolePage:
    """A console page in the browser: every request is routed and any that is not for
    127.0.0.1 is refused and recorded; page errors are recorded."""

    def __init__(self, page: Any, artifacts: Path) -> None:
        self.page = page
        self.artifacts = artifacts
        self.requests: list[str] = []
        self.foreign: list[str] = []
        self.errors: list[str] = []

    async def route(self, route: Any) -> None:
        url = route.request.url
        self.requests.append(url)
        if urlsplit(url).hostname != "127.0.0.1":
            self.foreign.append(url)
            await route.abort()
        else:
            await route.continue_()

    async def js(self, expression: str) -> Any:
        return await self.page.evaluate(expression)

    async def wait(self, expression: str, timeout: float = 20.0, what: str = "") -> Any:
        """Poll ``expression`` until it is truthy (the page's CSP forbids the string
        evaluation wait_for_function uses)."""
        deadline = asyncio.get_running_loop().time() + timeout
        while True:
            value = await self.page.evaluate(expression)
            if value:
                return value
            if asyncio.get_running_loop().time() > deadline:
                last = await self.page.evaluate(
                    "window.afaConsole ? afaConsole.stats.lastError : 'no console'")
                raise AssertionError(f"timed out waiting for {what or expression}; page "
                                     f"errors: {self.errors}; last view error: {last}")
            await asyncio.sleep(0.1)

    async def until(self, predicate: Any, what: str, timeout: float = 20.0) -> None:
        """Poll ``predicate()`` on the server's side until it is true: what the page sends
        (a subscription, say) reaches the server some time after the page has shown it."""
        await eventually(predicate, timeout, what, interval=0.05)

    async def shot(self, name: str, selector: str | None = None) -> Path:
        path = self.artifacts / f"{name}.png"
        if selector is None:
            await self.page.screenshot(path=str(path), full_page=True)
        else:
            await self.page.locator(selector).screenshot(path=str(path))
        return path


@pytest.fixture
def open_console(browser: Any, artifacts: Path) -> Any:
    async def opener(url: str, viewport: tuple[int, int] = (1600, 1300)) -> ConsolePage:
        context = await browser.new_context(viewport={"width": viewport[0],
                                                      "height": viewport[1]})
        page = await context.new_page()
        console_page = ConsolePage(page, artifacts)
        await context.route("**/*", console_page.route)
        page.on("pageerror", lambda error: console_page.errors.append(str(error)))
        page.on("console", lambda message: console_page.errors.append(message.text)
                if message.type == "error" else None)
        page.on("websocket", lambda ws: console_page.requests.append(ws.url) or (
            console_page.foreign.append(ws.url)
            if urlsplit(ws.url).hostname != "127.0.0.1" else None))
        await page.goto(url, timeout=60_000)
        await console_page.wait("window.afaConsole && window.afaConsole.ready",
                                what="the first status message")
        return console_page

    return opener
