"""Compile the numba kernels the test suite runs into numba's on-disk cache, each once, before pytest starts.

``scripts/test.sh`` runs it (``python tests/compile_kernels.py [--jobs N]``).  On a cold cache (a fresh
clone) one scheme's step takes 5-60 s to compile and each run loop around it a few seconds more.  Left
to pytest, its two workers and the subprocesses of the command-line tests compile whichever kernels
they meet first, side by side, often the same ones at the same time (numba's cache is written when a
compile ends, so a second process that starts before then compiles again).  Here ``--jobs`` processes
(default: one per CPU) compile them once each, the costliest schemes first; pytest then only loads
them.  On a warm cache this takes a few seconds (loading, nothing compiled).

Nothing is asserted here: a kernel that fails to compile or run fails its tests, which say why.

One task per scheme of the integrator table.  Phase 1: the step with the test stepping driver around
it (``tests/core/test_integrators.py``) and the tracing run loop (``simulate``).  Phase 2, in the same
task: the summary and batch loops of the schemes the suite runs batches or summaries with
(``SUMMARY_INTEGRATORS``).  Phase 3, a task of its own: the events loop and batch of the schemes whose exact
contact events the CI tier records (``EVENT_INTEGRATORS``).  Tests of other kernels (the events loops of the
other contact schemes, forward Euler's summary loop) are in the long tier.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: Integrators besides the presets' defaults whose summary loop and batch kernel the suite runs (the
#: others' only through their tracing loop): contact-substep (the accuracy study's reference),
#: contact-dop853, rk4 and verlet (tests/test_simulate.py, tests/core/test_kernel_speed_equivalence.py).
SUMMARY_INTEGRATORS = ("rk4", "contact-substep", "contact-dop853", "verlet")
#: Integrators whose events loop and batch kernel the suite runs (tests/core/test_events.py, study p's quick run).
EVENT_INTEGRATORS = ("contact-tsit5",)


def _summary_integrators():
    """SUMMARY_INTEGRATORS and every preset's default integrator."""
    from dicetrace.params import PRESETS

    return {p.integrator for p in PRESETS.values()} | set(SUMMARY_INTEGRATORS)


def _ic():
    from dicetrace.ics import seed_slice

    return seed_slice(1.65, 3.9)


def _phase1(name: str) -> str:
    """The step (through the test driver) and the tracing loop of integrator ``name``."""
    sys.path.insert(0, str(HERE / "core"))
    import test_integrators as ti

    from dicetrace.simulate import Record, simulate

    ti.run(name, ti.kparams(integrator=name), 1e-3, 1e-3, [0.0, 0.0, 15.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    simulate(_ic(), integrator=name, t_max_s=0.05, record=Record(states=True))
    return name


def _phase2(task: str) -> str:
    """Integrator ``task``'s summary loop and batch kernel."""
    import numpy as np

    from dicetrace.core import kernels
    from dicetrace.params import make_config
    from dicetrace.core.loop import BATCH_BLOCK
    from dicetrace.simulate import simulate_batch

    cfg = make_config("seed", integrator=task, t_max_s=0.05)
    kernels.run_summary(cfg.kernel_inputs(_ic()).ics, cfg.initial_offsets(), cfg.kernel_params(),
                     cfg.numerics.integrator_id, np.zeros(64, np.uint8), np.zeros(64, np.int32))
    simulate_batch(np.tile(_ic(), (BATCH_BLOCK + 1, 1)), config=cfg, threads=1)
    return task


def _phase3(task: str) -> str:
    """Integrator ``task``'s events loop and batch kernel (exact contact events)."""
    import numpy as np

    from dicetrace.core.loop import BATCH_BLOCK
    from dicetrace.simulate import Record, simulate_batch

    simulate_batch(np.tile(_ic(), (BATCH_BLOCK + 1, 1)), preset="physical", integrator=task, t_max_s=0.05,
                   threads=1, record=Record.events_only())
    return task


def _scheme(task: tuple[str, str]) -> str:
    """One task: ``("step", name)`` phase 1 and, where the suite needs them, phase 2 of integrator ``name``'s
    scheme; ``("events", name)`` its events kernels (phase 3)."""
    kind, name = task
    if kind == "events":
        _phase3(name)
        return f"{name} (events)"
    _phase1(name)
    if name in _summary_integrators():
        _phase2(name)
    return name


def _tasks(names) -> list[tuple[str, str]]:
    """The tasks, in the order the pool takes them: one per scheme (``_costliest_first``), and the events kernels
    as a task of their own right after the first (each is about as costly as a contact scheme's step and loops,
    so two processes then share the costliest work instead of one doing it all after its step)."""
    steps = [("step", n) for n in _costliest_first(names)]
    return steps[:1] + [("events", ev) for ev in EVENT_INTEGRATORS] + steps[1:]


def _costliest_first(names):
    """One integrator per scheme, the error-controlled and sub-stepping schemes first, then by falling order."""
    from dicetrace.integrators import INTEGRATORS

    by_scheme = {}
    for name, spec in INTEGRATORS.items():
        by_scheme.setdefault(spec.scheme, name)
    chosen = [n for n in by_scheme.values() if n in names]
    return sorted(chosen, key=lambda n: (not INTEGRATORS[n].substepped, -INTEGRATORS[n].order))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="processes (default: one per CPU)")
    args = ap.parse_args(argv)

    from dicetrace.core._jit import CACHE
    from dicetrace.integrators import INTEGRATORS

    if not CACHE:
        print("compile_kernels: DICETRACE_CACHE is off, nothing to keep; skipped")
        return 0
    t0 = time.perf_counter()
    # One task per scheme (its step, tracing loop, and where the suite needs them its summary loop and batch
    # kernel, which load the step from the cache): no process waits on another, and none compiles a step twice.
    tasks = _tasks(INTEGRATORS)
    with ProcessPoolExecutor(max_workers=max(1, args.jobs), mp_context=get_context("spawn")) as pool:
        for done in pool.map(_scheme, tasks):
            print(f"compile_kernels: {done} ready ({time.perf_counter() - t0:.0f} s)", flush=True)
    print(f"compile_kernels: every kernel compiled or loaded in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
