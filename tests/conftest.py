"""Shared fixtures: the reference data of the 2019 program (tests/data/reference)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


def _reference_dir() -> Path | None:
    for cand in (
        os.environ.get("DICETRACE_REFERENCE"),
        REPO / "tests" / "data" / "reference",
    ):
        if cand and (Path(cand) / "writeup_points.csv").exists():
            return Path(cand)
    return None


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    d = _reference_dir()
    if d is None:
        pytest.skip("reference data of the 2019 program not found")
    return d
