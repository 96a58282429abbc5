"""Headless Chromium for page tests (Debian's chromium, driven by Playwright's async API).

Async, not sync: the sync API runs its dispatcher in greenlets inside the test process, and a
C-level abort there would end the whole suite with no test named (CI once died of a SIGABRT
just after the browser test; the async API needs no greenlet)."""

from __future__ import annotations

import shutil
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

# The flags the machine's notes prescribe for a closed network; SwiftShader gives WebGL without a GPU.
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def chromium_path() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no Chromium installed (.ci/run installs Debian's chromium; apt-get install chromium)")


@asynccontextmanager
async def browser_page() -> AsyncIterator[Any]:
    """A fresh page in headless Chromium; use inside ``asyncio.run``."""
    try:
        from playwright.async_api import async_playwright
    except ImportError:
        pytest.skip("playwright is not installed (pip install playwright)")
    path = chromium_path()
    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=path, args=ARGS)
        try:
            yield await browser.new_page(viewport={"width": 1200, "height": 1400})
        finally:
            await browser.close()
