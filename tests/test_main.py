"""``python -m dicetrace`` is the ``dicetrace`` command."""

from __future__ import annotations

import subprocess
import sys


def test_python_m_dicetrace_runs_the_command_with_its_exit_codes():
    bad = subprocess.run([sys.executable, "-m", "dicetrace", "simulate", "--preset", "nosuch"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "--preset" in bad.stderr and "nosuch" in bad.stderr
    assert "Traceback" not in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
