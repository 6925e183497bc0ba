"""The compile notice: a spinner while numba compiles, in a terminal only, and the first record's cold start."""

from __future__ import annotations

import io
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from dicetrace.commands._compiling import compile_notice


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _fresh_kernel():
    """A function numba has never compiled (a new closure each call, no cache)."""
    k = time.perf_counter_ns()

    @numba.njit(cache=False)
    def f(x):
        return x * 2 + k

    return f


def test_a_terminal_sees_the_compile_and_its_time():
    out = _Terminal()
    with compile_notice(out):
        assert _fresh_kernel()(3) > 6
    text = out.getvalue()
    assert "compiling the simulation kernels" in text
    assert "dicetrace: compiled the simulation kernels in" in text


def test_no_compile_no_notice_and_off_a_terminal_nothing():
    f = _fresh_kernel()
    f(1)  # compiled before the block: the call inside loads nothing new
    out = _Terminal()
    with compile_notice(out):
        f(2)
    assert out.getvalue() == ""
    plain = io.StringIO()
    with compile_notice(plain):
        _fresh_kernel()(3)
    assert plain.getvalue() == ""


@pytest.mark.slow
@pytest.mark.long
def test_a_cold_record_says_it_is_compiling_within_seconds(tmp_path):
    """DICETRACE_CACHE=0 (nothing cached): in a terminal, the notice comes before the compile is done
    (measured 1.2 s after the start of a compile of several seconds), and the record finishes."""
    exe = Path(sys.executable).with_name("dicetrace")
    master, slave = pty.openpty()
    env = dict(os.environ, DICETRACE_CACHE="0", COLUMNS="120")
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(exe), "record", "--slice", "seed", "--at", "1.65,3.9", "--out", str(tmp_path / "r.rrd")],
                            stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
    os.close(slave)
    buf, first = b"", None
    try:
        while time.perf_counter() - t0 < 240:
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                try:
                    data = os.read(master, 4096)
                except OSError:  # the child closed the terminal
                    break
                if not data:
                    break
                buf += data
                if first is None and b"compiling the simulation kernels" in buf:
                    first = time.perf_counter() - t0
            elif proc.poll() is not None:
                break
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)
    text = buf.decode(errors="replace")
    assert proc.returncode == 0, text[-2000:]
    # the notice comes first, while the compile is still running: before its end is reported, and sooner after
    # the start than the compile lasted (a ratio of two times on the same machine, not a wall-time limit)
    assert first is not None, text[-500:]
    done = re.search(r"compiled the simulation kernels in ([\d.]+) s", text)
    assert done and text.index("compiling the simulation kernels") < done.start() and "wrote" in text, text[-800:]
    assert first < float(done.group(1)), (first, done.group(0))
    assert (tmp_path / "r.rrd").stat().st_size > 10_000
