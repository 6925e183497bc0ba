"""Fixtures of the explorer tests: the app under starlette's TestClient (the headless chromium, ``browser``, is
tests/conftest.py's)."""

from __future__ import annotations

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
