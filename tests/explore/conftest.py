"""Fixtures of the explorer tests: the app under starlette's TestClient."""

from __future__ import annotations

import pytest

from explore_helpers import RES, WINDOW


@pytest.fixture
def client(tmp_path):
    from starlette.testclient import TestClient

    from dicetrace.explore import View, create_app
    from dicetrace.explore.view import parse_window

    app = create_app(View(window=parse_window(WINDOW), res=(RES, RES)), out=tmp_path / "saved")
    with TestClient(app) as c:
        yield c
