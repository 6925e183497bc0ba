"""Long runs: estimated before they start, and stopped by Ctrl-C within a second once they run (issue 47 C).

Every kernel returns to Python after a bounded slice of steps (``core.kernels.SLICE_STEPS``; a batch's calls
are sized to about a quarter of a second), so a SIGINT is seen within a slice: the command says so in one line
and exits 130, the Python API raises KeyboardInterrupt.  A time cap so long that a throw may run for over ten
minutes is refused up front without ``--yes``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

#: Straight up at 1e9 cm/s: the die never comes down before a 1e8 s time cap (1e11 steps of 1 ms).
FLYAWAY = "0,0,1e9,0,100,0"


def test_an_absurd_time_cap_is_refused_without_yes(dicetrace_cli, tmp_path):
    """``simulate --t-max 1e8``: 1e11 steps, refused in one line that names the steps, the time and --yes; nothing
    runs (no kernel is called: this takes no time)."""
    res = dicetrace_cli("simulate", "--ic", FLYAWAY, "--t-max", "1e8", cwd=tmp_path)
    code, out, err = res.returncode, res.stdout, res.stderr
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("dicetrace: error: --t-max 100000000 at --dt 0.001")
    assert "100,000,000,000 steps" in err and "--yes" in err


def test_a_long_but_reasonable_time_cap_runs_without_yes(dicetrace_cli, tmp_path):
    """A time cap of 10,000 s (1e7 steps, at most about 20 s at the slowest step) needs no --yes."""
    res = dicetrace_cli("simulate", "--slice", "seed", "--at", "1.65,3.9", "--t-max", "1e4", cwd=tmp_path)
    code, out, err = res.returncode, res.stdout, res.stderr
    assert code == 0, err
    assert "settled" in out


def _interrupted_after(cmd: list[str], wait: float, tmp_path):
    """Start ``cmd`` (a new interpreter), let it run ``wait`` seconds, send SIGINT: (returncode, seconds to exit,
    stderr)."""
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    time.sleep(wait)
    assert proc.poll() is None, proc.stderr.read()  # still running: the interrupt lands inside the run
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the run ignored Ctrl-C for 30 s")
    return proc.returncode, time.monotonic() - t0, err


@pytest.mark.slow
def test_ctrl_c_stops_a_flyaway_simulate_within_a_second(tmp_path):
    """The flyaway throw with --yes runs (it would for days); Ctrl-C ends it at once: one line, exit 130."""
    code, took, err = _interrupted_after(
        [sys.executable, "-m", "dicetrace", "simulate", "--ic", FLYAWAY, "--t-max", "1e8", "--yes"], 8.0, tmp_path)
    assert code == 130, err
    assert err.strip().splitlines()[-1] == "dicetrace: interrupted" and "Traceback" not in err
    assert took < 5.0  # a slice is milliseconds; the rest is the interpreter's exit


@pytest.mark.slow
def test_ctrl_c_stops_the_api_and_a_batch(tmp_path):
    """From Python: ``simulate_batch`` of dice that bounce for ever (no damping, no friction: they never settle)
    raises KeyboardInterrupt on Ctrl-C, between two calls of the batch kernel."""
    code = (
        "import numpy as np\n"
        "from dicetrace.simulate import simulate_batch\n"
        "ics = np.tile([0.0, 0.0, 50.0, 0.0, 100.0, 0.0], (64, 1))\n"
        "simulate_batch(ics, preset='physical', gamma=0.0, mu=0.0, t_max_s=1e7, threads=1)\n"
    )
    rc, took, err = _interrupted_after([sys.executable, "-c", code], 10.0, tmp_path)
    assert rc != 0 and "KeyboardInterrupt" in err
    assert took < 5.0
