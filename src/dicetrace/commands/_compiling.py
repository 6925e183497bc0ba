"""Telling the user that numba is compiling: a spinner while the kernels compile, then how long it took.

The kernels are compiled on first use and cached on disk (``core._jit``), so
a first run spends seconds in numba that later runs do not.  A command run
in a terminal shows a spinner from the moment a compile starts (numba's
``numba:compile`` event fires only on a real compile, never on a cache load)
and, at the end, one line with the time it took.  Off a terminal (pipes,
logs, tests) nothing is printed: standard error stays what the command says.
"""

from __future__ import annotations

import contextlib
import sys
import time

from rich.console import Console

from dicetrace.compile_clock import quiet_compiles


def _message() -> str:
    from dicetrace.core._jit import CACHE  # lazy: keeps `dicetrace --help` fast (imports numba)

    why = "first run only: they are cached for later runs" if CACHE else "DICETRACE_CACHE=0: not cached"
    return f"compiling the simulation kernels ({why})…"


@contextlib.contextmanager
def compile_notice(stream=None):
    """Within this block, show a spinner on ``stream`` (default stderr) while numba compiles, if it is a terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError, OSError):
        tty = False
    with quiet_compiles():  # a command says it with its spinner, on a terminal only (the API's line is not its)
        if not tty:
            yield
        else:
            with _spinner(stream):
                yield


@contextlib.contextmanager
def _spinner(stream):
    from numba.core import event  # lazy: keeps `dicetrace --help` fast (imports numba)

    console = Console(file=stream, stderr=stream is sys.stderr)
    state = {"depth": 0, "t0": 0.0, "total": 0.0, "status": None}

    class _Listener(event.Listener):
        def on_start(self, ev):
            if state["depth"] == 0:
                state["t0"] = time.perf_counter()
                state["status"] = console.status(_message(), spinner="dots")
                state["status"].start()
            state["depth"] += 1

        def on_end(self, ev):
            state["depth"] -= 1
            if state["depth"] == 0 and state["status"] is not None:
                state["status"].stop()
                state["status"] = None
                state["total"] += time.perf_counter() - state["t0"]

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        yield
    finally:
        event.unregister("numba:compile", listener)
        if state["status"] is not None:  # interrupted mid-compile
            state["status"].stop()
        if state["total"] > 0:
            with contextlib.suppress(OSError, ValueError):
                console.print(f"dicetrace: compiled the simulation kernels in {state['total']:.1f} s", highlight=False)
