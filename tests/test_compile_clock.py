"""Rates are of the throws, not of numba's compiler: compile time is counted apart wherever a rate is printed.

A first run on a cold kernel cache spends most of its time compiling ("441 throws, 134.1 s, 3/s").  The kernels
of this process are cached, so each test makes numba really compile something new inside the timed work (a
fresh ``njit`` function, its first call), and checks that the clock saw it and that the printed rate is over the
time left.
"""

from __future__ import annotations

import re
import time

import numba
import pytest

from dicetrace.compile_clock import CompileClock, rate_text, running_rate, time_text


def _fresh_compile() -> None:
    """A real numba compile (a new function, not cached), of a few tenths of a second."""
    @numba.njit(cache=False)
    def f(n):
        s = 0.0
        for i in range(n):
            s += i ** 0.5
        return s

    f(10)


def test_the_clock_counts_a_compile_and_not_a_run():
    t0 = time.perf_counter()
    with CompileClock() as clock:
        _fresh_compile()
    wall = time.perf_counter() - t0
    assert 0 < clock.seconds <= wall
    spent = clock.seconds
    time.sleep(0.01)
    assert clock.seconds == spent  # stopped: nothing more is counted

    @numba.njit(cache=False)
    def g(x):
        return x + 1

    g(1)  # compiled outside any clock
    with CompileClock() as idle:
        g(2)  # already compiled: a run, no compile
        time.sleep(0.02)
    assert idle.seconds == 0.0


def test_rate_text_says_compile_apart_and_rates_the_running_time():
    assert rate_text(441, "throws", 3.1) == "441 throws in 3.1 s, 142/s"
    assert rate_text(441, "throws", 134.1, 131.0) == ("441 throws in 134.1 s (131.0 s compiling the kernels, 3.1 s "
                                                       "running), 142/s")
    assert rate_text(10_000, "ICs", 2.0, 1.0, " ICs/s") == ("10,000 ICs in 2.0 s (1.0 s compiling the kernels, 1.0 s "
                                                            "running), 10,000 ICs/s")
    assert running_rate(0, 1.0, 0.5) == 0.0 and running_rate(5, 1.0, 1.0) == 0.0


def _compiling_first(real):
    def chunks(*args, **kwargs):
        _fresh_compile()
        yield from real(*args, **kwargs)
    return chunks


def test_a_scan_reports_its_compile_apart(tmp_path, monkeypatch):
    from dicetrace.ics import Grid
    from dicetrace.scan import runner, scan

    monkeypatch.setattr(runner, "_chunks", _compiling_first(runner._chunks))
    report = scan(Grid("seed", "red-sea", 6), tmp_path / "s")
    assert report.ics_computed == 36 and 0 < report.compile_s < report.wall_s
    assert report.rate_ics_s == pytest.approx(36 / (report.wall_s - report.compile_s))


def test_the_scan_command_prints_the_compile_apart(dicetrace_cli, tmp_path, monkeypatch):
    from dicetrace.scan import runner

    monkeypatch.setattr(runner, "_chunks", _compiling_first(runner._chunks))
    res = dicetrace_cli("scan", "--slice", "seed", "--window", "red-sea", "--res", "6", "--out", str(tmp_path / "s"),
                        cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    m = re.search(r"36 ICs in ([\d.]+) s \(([\d.]+) s compiling the kernels, ([\d.]+) s running\), ([\d,]+) ICs/s",
                  res.stderr)
    assert m, res.stderr
    wall, comp, run = map(float, m.groups()[:3])
    rate = float(m.group(4).replace(",", ""))
    assert comp > 0 and abs(wall - comp - run) < 0.11
    assert 36 / (run + 0.1) <= rate <= 36 / max(run - 0.1, 1e-3)  # over the running time (printed to 0.1 s)


def test_a_study_logs_its_grids_compile_apart(tmp_path, monkeypatch, capsys):
    from dicetrace.analysis import simulator
    from dicetrace.studies.context import Context, Options

    real = simulator.sample_window

    def sample_window(*args, **kwargs):
        t0 = time.perf_counter()
        _fresh_compile()
        s = real(*args, **kwargs)
        s.wall_s = time.perf_counter() - t0  # as the real one measures a compile of its own kernels: inside
        return s

    monkeypatch.setattr(simulator, "sample_window", sample_window)
    ctx = Context("settle", Options(quick=True), tmp_path / "cache")
    ctx.sample("red-sea", 5)
    out = capsys.readouterr().out
    m = re.search(r"simulated red-sea at \(5, 5\) \(25 throws in ([\d.]+) s \(([\d.]+) s compiling the kernels, "
                  r"([\d.]+) s running\), ([\d,]+)/s\)", out)
    assert m, out
    wall, comp, run = map(float, m.groups()[:3])
    assert comp > 0 and 25 / (run + 0.1) <= float(m.group(4).replace(",", "")) <= 25 / max(run - 0.1, 1e-3)


def test_time_text_says_compile_apart():
    assert time_text(3.14) == "3.1 s"
    assert time_text(12.4, 10.2, ".0f") == "12 s (10 s compiling the kernels, 2 s running)"


# -- the Python API says once that it compiles -----------------------------------------------------------------

_FIRST = """
import sys
import numpy as np
import dicetrace.simulate  # registers the notice
from dicetrace.core.model import top4_mask
top4_mask(np.arange(8.0))  # a kernel of dicetrace's, compiled (or loaded) on this call
top4_mask(np.arange(8.0))
print("done")
"""


def _first(env_extra):
    import os
    import subprocess
    import sys

    env = {**os.environ, **env_extra}
    return subprocess.run([sys.executable, "-c", _FIRST], capture_output=True, text=True, timeout=300, env=env)


@pytest.mark.slow
def test_the_first_compile_is_said_once_and_a_cache_load_says_nothing(tmp_path):
    """A first call from Python that compiles one of dicetrace's kernels says so once on standard error (the
    command line's spinner aside); the same kernel loaded from the cache in a new interpreter says nothing."""
    from dicetrace.compile_clock import FIRST_COMPILE

    env = {"DICETRACE_CACHE_DIR": str(tmp_path / "kernels")}
    cold = _first(env)
    assert cold.returncode == 0, cold.stderr
    assert cold.stderr.splitlines().count(FIRST_COMPILE) == 1, cold.stderr
    warm = _first(env)
    assert warm.returncode == 0 and FIRST_COMPILE not in warm.stderr, warm.stderr


def _fresh_dicetrace_compile() -> None:
    """A real compile of a new function that the notice takes for one of dicetrace's (its module's name)."""
    def g(n):
        return n + 1

    g.__module__ = "dicetrace.test_fresh"
    numba.njit(cache=False)(g)(1)


def test_quiet_compiles_says_nothing(capsys, monkeypatch):
    """Outside ``quiet_compiles`` the first compile of a dicetrace kernel says so; inside it (the command line,
    and these tests' processes) it says nothing."""
    from dicetrace import compile_clock

    compile_clock.say_first_compile()
    monkeypatch.setitem(compile_clock._NOTICE, "quiet", 0)
    monkeypatch.setitem(compile_clock._NOTICE, "said", False)
    with compile_clock.quiet_compiles():
        _fresh_dicetrace_compile()
    assert compile_clock.FIRST_COMPILE not in capsys.readouterr().err
    _fresh_dicetrace_compile()
    assert capsys.readouterr().err.count(compile_clock.FIRST_COMPILE) == 1
