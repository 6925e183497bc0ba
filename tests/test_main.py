"""``python -m dicetrace`` is the ``dicetrace`` command."""

from __future__ import annotations

import subprocess
import sys


def test_python_m_dicetrace_runs_the_command_and_its_exit_codes():
    ok = subprocess.run([sys.executable, "-m", "dicetrace", "analyze", "--help"], capture_output=True, text=True)
    assert ok.returncode == 0 and "Usage: python -m dicetrace analyze" in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "dicetrace", "simulate", "--preset", "nosuch"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "nosuch" in bad.stderr and "Traceback" not in bad.stderr
