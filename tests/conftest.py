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


# -- golden files (tests/data/golden, see its README.md) --------------------------------------

GOLDEN_DIR = REPO / "tests" / "data" / "golden"
UPDATE_GOLDEN_ENV = "DICETRACE_UPDATE_GOLDEN"


def pytest_addoption(parser):
    parser.addoption(
        "--update-golden",
        action="store_true",
        default=False,
        help=f"rewrite the golden files in tests/data/golden from this checkout (or set {UPDATE_GOLDEN_ENV}=1); "
        "the golden tests are then skipped: review the change with git diff",
    )


@pytest.fixture(scope="session")
def update_golden(request) -> bool:
    """True when this run regenerates the golden files instead of checking them."""
    return bool(request.config.getoption("--update-golden")) or os.environ.get(UPDATE_GOLDEN_ENV, "") not in ("", "0")
