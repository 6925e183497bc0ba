"""Time spent compiling the numba kernels, told apart from the time they run: the clock behind every printed rate.

The kernels compile on first use (and load from numba's disk cache after), so a first run of a study or a
scan on a cold cache spends most of its time in numba's compiler: "441 throws, 134.1 s, 3/s" was mostly
compiling.  :class:`CompileClock` adds up the wall time of numba's ``numba:compile`` events (fired on a real
compile, never on a cache load; nested compiles, and compiles on several threads at once, count once) while it
runs, and :func:`rate_text` prints a count with its time and the rate over the time not spent compiling.
Compiles in other processes (a Dask cluster's workers) are not seen.
"""

from __future__ import annotations

import threading
import time


class CompileClock:
    """Seconds of wall time during which numba compiled, from :meth:`start` (or entering ``with``) to :meth:`stop`.

    ``seconds`` includes a compile still in progress."""

    def __init__(self) -> None:
        self._done = 0.0
        self._depth = 0
        self._t0 = 0.0
        self._lock = threading.Lock()
        self._listener = None

    @property
    def seconds(self) -> float:
        with self._lock:
            return self._done + (time.perf_counter() - self._t0 if self._depth else 0.0)

    def start(self) -> CompileClock:
        from numba.core import event  # lazy: keeps `dicetrace --help` fast (imports numba)

        clock = self

        class _Listener(event.Listener):
            def on_start(self, ev):
                with clock._lock:
                    if clock._depth == 0:
                        clock._t0 = time.perf_counter()
                    clock._depth += 1

            def on_end(self, ev):
                with clock._lock:
                    clock._depth = max(clock._depth - 1, 0)
                    if clock._depth == 0:
                        clock._done += time.perf_counter() - clock._t0

        self._listener = _Listener()
        event.register("numba:compile", self._listener)
        return self

    def stop(self) -> float:
        """Stop listening; returns :attr:`seconds`."""
        if self._listener is not None:
            from numba.core import event

            event.unregister("numba:compile", self._listener)
            self._listener = None
        return self.seconds

    def __enter__(self) -> CompileClock:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def running_rate(n: float, wall_s: float, compile_s: float = 0.0) -> float:
    """``n`` per second of the time not spent compiling (0 where there was none)."""
    run = wall_s - compile_s
    return n / run if run > 0 and n > 0 else 0.0


def time_text(wall_s: float, compile_s: float = 0.0, spec: str = ".1f") -> str:
    """``"3.1 s"``, or with a compile ``"134.1 s (131.0 s compiling the kernels, 3.1 s running)"``."""
    if compile_s >= 0.05:
        return (f"{wall_s:{spec}} s ({compile_s:{spec}} s compiling the kernels, "
                f"{max(wall_s - compile_s, 0.0):{spec}} s running)")
    return f"{wall_s:{spec}} s"


def rate_text(n: int, unit: str, wall_s: float, compile_s: float = 0.0, rate_unit: str = "/s") -> str:
    """``"441 throws in 3.1 s, 142/s"``, or with a compile ``"441 throws in 134.1 s (131.0 s compiling the kernels,
    3.1 s running), 142/s"``: the rate is always over the running time."""
    return f"{n:,} {unit} in {time_text(wall_s, compile_s)}, {running_rate(n, wall_s, compile_s):,.0f}{rate_unit}"


# ------------------------------------------------------------------ the first compile, said once (the Python API)

#: What the first compile of a process says on standard error (the command line shows a spinner instead).
FIRST_COMPILE = (
    "dicetrace: compiling the simulation kernels (the first run on this machine only: about 10-30 s for the seed "
    "path, 1-2 min for a contact integrator such as physical's, a little more for events or a batch; later runs "
    "load them from the cache)"
)

_NOTICE = {"listener": None, "said": False, "quiet": 0}
_NOTICE_LOCK = threading.Lock()


def say_first_compile() -> None:
    """From now on, say :data:`FIRST_COMPILE` on standard error once, when numba first compiles one of dicetrace's
    kernels in this process (a cache load says nothing); idempotent.  :func:`quiet_compiles` silences it."""
    with _NOTICE_LOCK:
        if _NOTICE["listener"] is not None or _NOTICE["said"]:
            return
        from numba.core import event

        class _Listener(event.Listener):
            def on_start(self, ev):
                if _NOTICE["said"] or _NOTICE["quiet"]:
                    return
                fn = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__module__", "") or ""
                if not fn.startswith("dicetrace."):
                    return
                _NOTICE["said"] = True
                import sys

                try:
                    sys.stderr.write(FIRST_COMPILE + "\n")
                    sys.stderr.flush()
                except (OSError, ValueError, AttributeError):  # no usable standard error: nothing to say
                    pass

            def on_end(self, ev):
                pass

        _NOTICE["listener"] = _Listener()
        event.register("numba:compile", _NOTICE["listener"])


class quiet_compiles:
    """Within the block, :func:`say_first_compile` says nothing (the command line shows its own spinner)."""

    def __enter__(self):
        with _NOTICE_LOCK:
            _NOTICE["quiet"] += 1
        return self

    def __exit__(self, *exc):
        with _NOTICE_LOCK:
            _NOTICE["quiet"] -= 1
