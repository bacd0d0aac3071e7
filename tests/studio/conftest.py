"""Fixtures of the studio tests: a real server on loopback and Debian's chromium via Playwright.

Browser tests skip with the reason when Playwright or /usr/bin/chromium is missing, and fail
instead when the environment variable ``CI`` is set (CI must run them).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tagbot.io.planfile import tag_from_dict
from tagbot.studio.server import Studio, StudioServer

CHROMIUM = os.environ.get("TAGBOT_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]

PLAN = {
    "format": "tagbot-plan",
    "version": 1,
    "model": "gamma",
    "units": "mm",
    "plans": [
        {
            "start": 0.0,
            "targets": [[0.0, 0.0], [60.0, 10.0], [90.0, 60.0], [140.0, 30.0]],
            "strokes": [
                {"dt": 0.0, "mu": -1.6, "sigma": 0.34, "phi1": 0.3, "phi2": -0.2},
                {"dt": 0.2, "mu": -1.6, "sigma": 0.34, "phi1": -0.4, "phi2": 0.5},
                {"dt": 0.25, "mu": -1.6, "sigma": 0.34, "phi1": 0.2, "phi2": 0.1},
            ],
        }
    ],
}
"""A small ΓΛ* plan the editing tests start from."""


def browser_missing() -> str | None:
    """Why the browser tests cannot run here, or None."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "Playwright for Python is not installed (pip install -e '.[test]')"
    if not (os.path.exists(CHROMIUM) or shutil.which(CHROMIUM)):
        return f"{CHROMIUM} is missing (apt-get install chromium)"
    return None


def require_browser() -> None:
    reason = browser_missing()
    if reason is None:
        return
    if os.environ.get("CI"):
        pytest.fail(f"browser tests must run in CI, but {reason}", pytrace=False)
    pytest.skip(reason)


class Running:
    """A studio being served, with an HTTP client that carries its token."""

    def __init__(self, server: StudioServer, runs: Path) -> None:
        self.server = server
        self.studio = server.studio
        self.runs = runs
        self.base = f"http://127.0.0.1:{server.port}"
        self.url = server.url
        self.client = httpx.Client(
            base_url=self.base, headers={"X-Tagbot-Token": self.studio.token}, timeout=120
        )

    def plan(self) -> dict[str, Any]:
        response = self.client.get("/api/plan")
        assert response.status_code == 200, response.text
        return response.json()  # type: ignore[no-any-return]

    def load(self, plan: dict[str, Any]) -> None:
        response = self.client.put("/api/plan", json=plan)
        assert response.status_code == 200, response.text

    def state(self) -> dict[str, Any]:
        return self.client.get("/api/state?arrays=json").json()  # type: ignore[no-any-return]


@pytest.fixture(scope="module")
def running(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Running]:
    """A studio on a free loopback port, warmed up; shut down (threads joined) afterwards."""
    folder = tmp_path_factory.mktemp("studio")
    studio = Studio(
        tag=tag_from_dict(PLAN), autosave=folder / "autosave.json", runs=folder / "runs"
    )
    server = StudioServer(studio)
    server.start()
    try:
        assert studio.ready.wait(300), "the studio did not warm up"
        run = Running(server, folder / "runs")
        yield run
        run.client.close()
    finally:
        server.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    """Debian's chromium, headless, driven by Playwright (no browser download)."""
    require_browser()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


@pytest.fixture
def page(browser: Any, running: Running) -> Iterator[Any]:
    """The studio's page, loaded on :data:`PLAN`, in a fresh browser context."""
    running.load(PLAN)
    context = browser.new_context(
        viewport={"width": 1400, "height": 860}, accept_downloads=True, bypass_csp=True
    )
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(running.url)
    page.wait_for_function("window.studio && window.studio.ready === true", timeout=120_000)
    try:
        yield page
    finally:
        context.close()
    assert not errors, f"errors on the page: {errors}"
