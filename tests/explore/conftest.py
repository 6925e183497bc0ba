"""Fixtures of the explorer tests: the app under starlette's TestClient, and a headless chromium (Playwright)."""

from __future__ import annotations

import shutil

import pytest

from explore_helpers import RES, WINDOW


@pytest.fixture
def client(tmp_path):
    from starlette.testclient import TestClient

    from dicetrace.explore import View, create_app
    from dicetrace.ics import get_window

    app = create_app(View(window=get_window(WINDOW), res=(RES, RES)), out=tmp_path / "saved")
    with TestClient(app, base_url="http://127.0.0.1") as c:  # a Host the explorer answers (not "testserver")
        yield c


CHROMIUM_CANDIDATES = ("chromium", "chromium-browser", "google-chrome")


def _chromium() -> str:
    for name in CHROMIUM_CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no chromium on PATH (Debian: apt-get install chromium)")


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium, headless, through Playwright (skipped, with the reason, where either is missing)."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (pip install playwright)")
    exe = _chromium()
    with sync_api.sync_playwright() as p:
        try:
            b = p.chromium.launch(executable_path=exe, headless=True,
                                  args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"])
        except Exception as e:  # a chromium that cannot start here
            pytest.skip(f"chromium {exe} does not start headless: {str(e).splitlines()[0]}")
        yield b
        b.close()
