"""Running ``dicetrace`` in-process: the console script's own ``run_app``, without a new interpreter.

A bad-input case then costs milliseconds instead of the ~2 s start-up of a
subprocess (numba's cache, rerun, pandas), so every case of the bad-input
tables can run in the fast inner loop.  The console script itself is still
run as a subprocess by a few tests of each command.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import pytest


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
