"""Stopping the processes a test starts (a dicetrace command, a Rerun server) as a user would, never leaving one running."""

from __future__ import annotations

import contextlib
import signal
import subprocess


def interrupt(proc: subprocess.Popen, timeout_s: float):
    """Ctrl-C ``proc`` (SIGINT) and wait up to ``timeout_s`` for it to end, killing it if it has not.

    Returns ``proc.communicate()``'s (stdout, stderr); after a kill ``proc.returncode`` is negative.
    """
    proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate(timeout=10)


@contextlib.contextmanager
def not_left_running(proc: subprocess.Popen):
    """Whatever happens in the block, ``proc`` is not left running after it: killed if it still is."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
