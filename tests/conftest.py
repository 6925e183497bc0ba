"""Shared fixtures: the reference data of the 2019 program (tests/data/reference), the golden-file switch, and
``dicetrace`` run in-process (the console script's own ``run_app``, without the ~2 s start-up of a new
interpreter: numba's cache, rerun, pandas), and a byte-for-byte snapshot of a folder."""

from __future__ import annotations

import os
import shutil
import stat
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


def pytest_configure(config):
    """The Python API's one line on the first compile (``compile_clock.say_first_compile``) stays quiet in the
    test processes, whose standard error some tests read line by line; ``tests/test_compile_clock.py`` checks it
    in fresh interpreters."""
    from dicetrace import compile_clock

    compile_clock.quiet_compiles().__enter__()


def pytest_collection_modifyitems(config, items):
    """A ``long`` test is also ``slow``: ``pytest -m "not slow"``, the inner loop, leaves it out as well."""
    for item in items:
        if item.get_closest_marker("long") is not None and item.get_closest_marker("slow") is None:
            item.add_marker(pytest.mark.slow)


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


# -- dicetrace in-process ------------------------------------------------------------------------


@dataclass
class CliResult:
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def dicetrace_cli(monkeypatch, capsys):
    """``run(*args, cwd=PATH)`` runs ``dicetrace ARGS`` in ``cwd`` and returns its exit code, stdout and stderr.

    An exception that escapes ``run_app`` (what a user would see as a
    traceback) propagates and fails the test.
    """
    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    def run(*args: str, cwd: Path) -> CliResult:
        capsys.readouterr()
        with monkeypatch.context() as mp:
            mp.chdir(cwd)
            mp.setattr(sys, "argv", ["dicetrace", *args])
            with pytest.raises(SystemExit) as exc:
                run_app(app)
        out, err = capsys.readouterr()
        code = exc.value.code
        return CliResult(0 if code is None else int(code), out, err)

    return run


def _assert_one_line_error(res: CliResult, *names: str) -> str:
    """Exit code 2, nothing on stdout, no traceback, and one ``dicetrace: error:`` line naming every one of ``names``."""
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr and "Traceback" not in res.stdout
    assert res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    line = lines[0]
    assert line.startswith("dicetrace: error: "), line
    missing = [n for n in names if n not in line]
    assert not missing, f"the message does not name {missing}: {line}"
    return line


@pytest.fixture
def assert_one_line_error():
    """``check(result, *names)``: exit code 2, nothing on stdout, no traceback, one error line naming all ``names``."""
    return _assert_one_line_error


# -- a folder, byte for byte ----------------------------------------------------------------------------


def _snapshot(root: Path) -> dict:
    """Everything under ``root``: type, bytes, mode and link target of each entry (symlinks not followed)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st_ = p.lstat()
            rel = str(p.relative_to(root))
            if stat.S_ISLNK(st_.st_mode):
                out[rel] = ("link", os.readlink(p))
            elif stat.S_ISDIR(st_.st_mode):
                out[rel] = ("dir", stat.S_IMODE(st_.st_mode))
            elif stat.S_ISREG(st_.st_mode):
                out[rel] = ("file", p.read_bytes(), stat.S_IMODE(st_.st_mode))
            else:
                out[rel] = ("special", stat.S_IFMT(st_.st_mode), st_.st_rdev)
    return out


@pytest.fixture
def snapshot():
    """``snapshot(folder)``: a dict of every entry's type, bytes, mode and link target, to compare before and after."""
    return _snapshot


# -- a headless browser ----------------------------------------------------------------------------

CHROMIUM_CANDIDATES = ("chromium", "chromium-browser", "google-chrome")


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium, headless, through Playwright (skipped, with the reason, where either is missing)."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (pip install playwright)")
    exe = next((shutil.which(n) for n in CHROMIUM_CANDIDATES if shutil.which(n)), None)
    if exe is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install chromium)")
    with sync_api.sync_playwright() as p:
        try:
            b = p.chromium.launch(executable_path=exe, headless=True,
                                  args=["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"])
        except Exception as e:  # a chromium that cannot start here
            pytest.skip(f"chromium {exe} does not start headless: {str(e).splitlines()[0]}")
        yield b
        b.close()
