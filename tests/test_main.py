"""``python -m dicetrace`` is the ``dicetrace`` command."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.slow  # seconds (a subprocess or a long fit): the quick loop skips it, CI runs it
def test_python_m_dicetrace_runs_the_command_with_its_exit_codes():
    bad = subprocess.run([sys.executable, "-m", "dicetrace", "simulate", "--preset", "nosuch"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "--preset" in bad.stderr and "nosuch" in bad.stderr
    assert "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


# -- Ctrl-C from the first moment ---------------------------------------------------------------------------------

#: A ``sitecustomize`` for the command's interpreter: the first import of the module named in
#: ``DICETRACE_TEST_SIGINT_AT`` sends this process SIGINT (Ctrl-C) from inside the import, as a user pressing
#: Ctrl-C while the command loads would; with ``DICETRACE_TEST_SIGINT_AS_IMPORTERROR`` the interrupt becomes the
#: ``ImportError: initialization failed`` an interrupted extension module raises.
_SIGINT_HOOK = '''
import os, signal, sys, time

class _InterruptAt:
    def __init__(self, name, convert):
        self.name, self.convert = name, convert

    def find_spec(self, name, path=None, target=None):
        if name != self.name:
            return None
        self.name = None
        try:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # the handler runs here, between two instructions
                time.sleep(0.001)
        except KeyboardInterrupt:
            if self.convert:
                raise ImportError("initialization failed") from None
            raise
        return None

if os.environ.get("DICETRACE_TEST_SIGINT_AT"):
    sys.meta_path.insert(0, _InterruptAt(os.environ["DICETRACE_TEST_SIGINT_AT"],
                                         bool(os.environ.get("DICETRACE_TEST_SIGINT_AS_IMPORTERROR"))))
'''


def _interrupted_run(tmp_path, entry: list[str], args: list[str], at: str, *, as_import_error: bool = False):
    import os

    hook = tmp_path / "hook"
    hook.mkdir(exist_ok=True)
    (hook / "sitecustomize.py").write_text(_SIGINT_HOOK)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(hook), *filter(None, [os.environ.get("PYTHONPATH")])]),
           "DICETRACE_TEST_SIGINT_AT": at}
    if as_import_error:
        env["DICETRACE_TEST_SIGINT_AS_IMPORTERROR"] = "1"
    return subprocess.run([*entry, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


def _entries() -> list:
    from pathlib import Path

    script = Path(sys.executable).parent / "dicetrace"
    return [pytest.param([sys.executable, "-m", "dicetrace"], id="python -m dicetrace"),
            pytest.param([str(script)], id="console script",
                         marks=pytest.mark.skipif(not script.is_file(), reason="no dicetrace console script here"))]


def _assert_interrupted(res) -> None:
    assert res.returncode == 130, (res.returncode, res.stderr)
    assert res.stderr.splitlines() == ["dicetrace: interrupted"], res.stderr  # one line, no traceback
    assert "Traceback" not in res.stdout


@pytest.mark.parametrize("entry", _entries())
def test_ctrl_c_while_the_command_loads_is_one_line_and_exit_130(tmp_path, entry):
    """Ctrl-C during the first imports (typer, before any command exists): once a 12-84-line traceback."""
    _assert_interrupted(_interrupted_run(tmp_path, entry, ["scan", "--window", "home", "--res", "3", "--out", "s"],
                                         "typer"))
    assert not (tmp_path / "s").exists()


def _console_script_only() -> list:
    """:func:`_entries` with ``python -m dicetrace`` in the long tier (the CI tier interrupts the console script:
    both entries run the same ``__main__`` guard, which ``test_ctrl_c_while_the_command_loads...`` covers for
    both)."""
    entries = _entries()
    return [pytest.param(*entries[0].values, id=entries[0].id, marks=[pytest.mark.long]), entries[1]]


@pytest.mark.slow
@pytest.mark.parametrize("entry", _console_script_only())
@pytest.mark.parametrize("args, at, as_import_error", [
    (["simulate", "--ic", "0,0,0,0,100,0"], "scipy", False),  # the commands' modules, still loading
    (["scan", "--window", "home", "--res", "3", "--out", "s"], "numba", False),  # inside the command
    (["analyze", "cells", "--quick", "--out", "a"], "numba", False),
    (["scan", "--window", "home", "--res", "3", "--out", "s"], "numba", True),  # an ImportError it caused
], ids=["simulate-loading", "scan-numba", "analyze-numba", "scan-import-error"])
def test_ctrl_c_in_a_commands_first_seconds_is_one_line_and_exit_130(tmp_path, entry, args, at, as_import_error):
    _assert_interrupted(_interrupted_run(tmp_path, entry, args, at, as_import_error=as_import_error))
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("value", ["abc", "0", "-2", "2.5"])
def test_a_numba_thread_count_that_is_none_is_one_line(tmp_path, monkeypatch, dicetrace_cli, assert_one_line_error,
                                                       value):
    """``NUMBA_NUM_THREADS=abc`` once let numba print its own traceback-shaped warning (and ``0`` fail its import):
    one line naming the variable, exit 2, nothing written."""
    monkeypatch.setenv("NUMBA_NUM_THREADS", value)
    res = dicetrace_cli("scan", "--window", "home", "--res", "3", "--out", "s", cwd=tmp_path)
    assert_one_line_error(res, "NUMBA_NUM_THREADS", repr(value), "integer >= 1")
    assert list(tmp_path.iterdir()) == []
