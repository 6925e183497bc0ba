"""Where a converged throw's time goes: the cost of each part of ``contact-tsit5``, in one run.

A part's cost is measured by a variant of the scheme that does that part
twice on the same inputs and keeps the second result (the first is summed
into a scratch cell that the step never reads, so the compiler cannot drop
it).  The trajectory is then the same, bit for bit: every variant's
statuses, step counts and outcomes are hashed and checked against the
plain scheme's, and a variant that changed them is flagged.  Its extra time
over the plain scheme, measured interleaved in one process on one thread
(best of ``--repeat`` rounds), is the part's own cost.  The parts:

* ``substep``: a whole Tsit5 sub-step (five stage force evaluations, the
  stage and result combinations, the new node offsets);
* ``stages``: only its five stage force evaluations (``erk.stage_wrench``);
* ``error``: the embedded error estimate;
* ``end forces``: the forces at a sub-step's end (its first-same-as-last
  stage, which the error estimate needs);
* ``cut test``: the test for a node that entered or left the ground inside
  the sub-step (the root of its height's Hermite interpolant when one did);
* ``interpolation``: the state at a step's end inside a sub-step that runs
  past it (Tsit5's continuous extension);
* ``step-end forces``: what the step hands the run loop there (in a summary
  loop only the node heights: ``STATE.lazy``);
* ``flight piece``: the lowest node's height after a piece of exact free
  flight near the ground;
* ``impact search``: locating the moment the lowest node reaches the ground.

Also printed: the attempts per throw (``Roll.substeps``, all causes) and the
macro steps per throw, so that a part's cost can be read per attempt or per
step.  The plain scheme is timed twice a round: the gap between its two
best times is the noise floor, below which a part's figure means nothing
(a few hundredths of a ms per throw on a shared 2-core machine; raise
``--repeat`` to lower it).  Each variant compiles for about a minute
(nothing is cached).

Usage: ``python benchmarks/bench_cost_split.py [--n 300] [--repeat 5]
[--preset physical] [--tol 1e-7] [--parts substep,stages,...]``.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import sys
import textwrap
import time
import types
from pathlib import Path

import numba
import numpy as np

from dicetrace.core import loop
from dicetrace.core._jit import jit
from dicetrace.core.contact_driver import free_piece, make_drive
from dicetrace.core.methods import erk, tsit5
from dicetrace.core.schemes import contact_tsit5
from dicetrace.core.state import new_states, new_work
from dicetrace.params import convert_l, make_config
from dicetrace.simulate import simulate
from dicetrace.studies.study_accuracy import T_MAX_S, sample_ics
from dicetrace.studies.text import tol_text

#: A scratch cell of the state that the step never reads before writing it
#: (``erk.dense_state`` sets all of ``wk.dn_w`` first): where a repeated part's
#: first result goes.
SINK = "wk.dn_w[6] += "
#: How much deeper than the factory ``make_drive`` its inner ``drive`` is indented.
DRIVE = "    "


def _jit(fn):
    """dicetrace's jit, uncached: the variants are this run's only."""
    return jit(fn, cache=False)


def _jit_inline(**options):
    """``jit(inline=...)`` as a decorator factory, uncached (an edited copy of one of the driver's inline parts)."""
    return lambda fn: jit(fn, cache=False, **options)


def _named_uncached(fn, name: str, doc: str):
    """``erk._named`` without the disk cache (a variant's factory is this run's only)."""
    fn.__name__ = fn.__qualname__ = name
    fn.__doc__ = doc
    return _jit(fn)


def _edited(fn, name: str, old: str, new: str, *more: str, env: dict | None = None):
    """``fn``'s source with ``old`` replaced once by ``new`` (and each further (old, new) pair of
    ``more`` after it), executed in ``fn``'s module (its globals, updated by ``env``) as ``name``."""
    fn = getattr(fn, "py_func", fn)  # a compiled part: its Python source
    src = textwrap.dedent(inspect.getsource(fn))
    src = src.replace(f"def {fn.__name__}(", f"def {name}(", 1)
    pairs = (old, new, *more)
    for a, b in zip(pairs[::2], pairs[1::2]):
        if a not in src:
            sys.exit(f"{Path(sys.argv[0]).stem or 'benchmarks'}: {fn.__name__}'s source no longer contains "
                     f"{a.strip()!r}; update this script")
        src = src.replace(a, b, 1)
    namespace = {**fn.__globals__, **(env or {})}
    exec(compile(src, inspect.getsourcefile(fn), "exec"), namespace)
    return namespace[name]


def _twice(line: str, result: str) -> str:
    """A source line, its result sunk, the line again (same indentation)."""
    indent = line[: len(line) - len(line.lstrip())]
    return line + f"{indent}{SINK}{result}\n" + line


def _drive_twice(name: str, line: str, result: str):
    """``make_drive`` with ``line`` (one or more lines of its ``drive``) done twice, the first result sunk."""
    return _edited(make_drive, name, line, _twice(line, result))


def method_module(tag: str, **replaced):
    """A copy of ``methods.tsit5`` (contact-tsit5's sub-step method) made at run time, ``replaced`` set in it."""
    mod = types.ModuleType(f"bench_method_{tag}")
    mod.__dict__.update({k: v for k, v in vars(tsit5).items() if not k.startswith("__")})
    mod.__dict__.update(replaced)
    return mod


def build_step(factory, tag: str, **replaced):
    """The contact step that ``factory`` (``make_drive`` or an edited copy) makes on ``methods.tsit5``,
    method with ``replaced`` swapped in, compiled uncached as ``step_<tag>``."""
    return factory(method_module(tag, **replaced), f"step_{tag}", cache=False)


def summary_roll(step, tag: str):
    """The summary run loop (``loop.make_roll``) on ``step``, uncached, without a specialised kernel."""
    scheme = types.ModuleType(f"bench_scheme_{tag}")
    scheme.step = step
    scheme.EXACT_FLIGHT = contact_tsit5.EXACT_FLIGHT
    scheme.WORK = contact_tsit5.WORK
    return loop.make_roll(scheme, trace=False, name=f"roll_{tag}", cache=False)


def variants() -> dict:
    """name -> (drive factory, the method's functions replaced) for the plain scheme and every part.

    A factory is ``make_drive`` or an edited copy of it (the part done twice
    in its ``drive``), called as ``make_drive`` is (:func:`build_step`).
    """
    tsub = erk.tsit5_substep
    terr = erk.tsit5_error

    @_jit
    def substep_twice(st, wk, kp, h, f0, f1, f2, t0, t1, t2):
        tsub(st, wk, kp, h, f0, f1, f2, t0, t1, t2)
        wk.dn_w[6] += wk.new_X[2]
        tsub(st, wk, kp, h, f0, f1, f2, t0, t1, t2)

    @_jit
    def error_twice(st, wk, kp, h, g0, g1, g2, q0, q1, q2):
        wk.dn_w[6] += terr(st, wk, kp, h, g0, g1, g2, q0, q1, q2)
        return terr(st, wk, kp, h, g0, g1, g2, q0, q1, q2)

    stage = "            g0, g1, g2, q0, q1, q2 = stage_wrench(y, off, kp, offs, st.F, st.uk, st.z, st.P, w0, w1, w2)\n"
    stages_factory = _edited(erk.erk_substep, "erk_substep_stages_twice", stage, _twice(stage, "g0 + q1"),
                             "return _named(", "return _named_uncached(", env={"_named_uncached": _named_uncached})
    stages_twice = stages_factory("tsit5_stages_twice", erk.TSIT5_STAGES, erk.TSIT5_A, erk.TSIT5_B)

    end_forces = (DRIVE + "            c5, g0, g1, g2, q0, q1, q2 = wrench_at(Xn[2], Un[0], Un[1], Un[2], wn0, wn1, wn2, offn, kp, st.F, st.uk,\n"
                  + DRIVE + "                                                   st.z, st.P)\n")
    cut = DRIVE + "        cut = first_crossing(Xw, Uw, Lw, offw, Xn, Un, Ln, offn, kp, hs, cmin)\n"
    interp = DRIVE + "            method.dense_state(st, wk, kp, 1.0 - st.ahead / wk.dn_h)\n"
    interp_forces = interp + DRIVE + "            return dense_end(st, kp)\n"
    # the parts outside the driver's closure (``free_piece``): an edited copy, put in the edited driver's globals
    piece = "    m1 = free_min_height(Xw, Uw, st.W, offw, kp, hs)\n"
    search = "    return PIECE_ENTRY, locate_entry(Xw, Uw, st.W, offw, kp, hs, m1), False\n"
    piece_twice = _edited(free_piece, "free_piece_twice", piece, _twice(piece, "m1"), "@jit(", "@_jit_inline(",
                          env={"_jit_inline": _jit_inline})
    search_twice = _edited(free_piece, "free_piece_search", search,
                           f"    {SINK}locate_entry(Xw, Uw, st.W, offw, kp, hs, m1)\n" + search, "@jit(", "@_jit_inline(",
                           env={"_jit_inline": _jit_inline})
    call = "kind, tau, last = free_piece("
    return {
        "plain": (make_drive, {}),
        "substep": (make_drive, dict(substep=substep_twice)),
        "stages": (make_drive, dict(substep=stages_twice)),
        "error": (make_drive, dict(error=error_twice)),
        "end forces": (_drive_twice("make_drive_end_forces", end_forces, "g0"), {}),
        "cut test": (_drive_twice("make_drive_cut", cut, "cut"), {}),
        "interpolation": (_drive_twice("make_drive_interp", interp, "st.X[2] + st.off[7, 2]"), {}),
        "step-end forces": (_edited(make_drive, "make_drive_interp_forces", interp_forces,
                                    interp + f"{DRIVE}            dense_end(st, kp)\n{DRIVE}            {SINK}st.z[0]\n"
                                    f"{DRIVE}            return dense_end(st, kp)\n"), {}),
        "flight piece": (_edited(make_drive, "make_drive_piece", call, "kind, tau, last = free_piece_twice(",
                                 env={"free_piece_twice": piece_twice}), {}),
        "impact search": (_edited(make_drive, "make_drive_search", call, "kind, tau, last = free_piece_search(",
                                  env={"free_piece_search": search_twice}), {}),
    }


@numba.njit(cache=False)
def _all(roll, ics, off0, kp, S, Wk, status, steps, outcome):
    cap = 1 << 16
    out = loop.RollOut(np.zeros(cap, np.uint8), np.zeros(cap, np.int32), np.zeros(0), np.zeros((0, loop.STATE_COLS)),
                       np.zeros((0, loop.FORCE_COLS)), np.zeros((0, loop.ENERGY_COLS)))
    for i in range(ics.shape[0]):
        status[i], steps[i], outcome[i], _ = roll(ics[i], off0, kp, S, Wk, out, False, 1 << 62)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--preset", default="physical")
    ap.add_argument("--tol", type=float, default=None, help="contact-tsit5's tolerance (default: the preset's)")
    ap.add_argument("--parts", default="", help="comma-separated parts (default: all)")
    args = ap.parse_args()
    try:
        cfg = make_config(args.preset, integrator="contact-tsit5", dt_s=1e-3, t_max_s=T_MAX_S, tol=args.tol)
    except (TypeError, ValueError) as exc:
        ap.error(str(exc))
    if args.n < 1:
        ap.error(f"--n must be at least 1, got {args.n}")
    table = variants()
    only = [p.strip() for p in args.parts.split(",") if p.strip()]
    unknown = [p for p in only if p not in table]
    if unknown:
        ap.error(f"unknown part(s) {', '.join(unknown)}; choose from {', '.join(list(table)[1:])}")
    names = ["plain"] + [p for p in table if p != "plain" and (not only or p in only)]
    numba.set_num_threads(1)
    ics = convert_l(sample_ics(n=args.n), "program", cfg.preset.l_convention)
    kin = cfg.kernel_inputs(ics)
    S, Wk = new_states(1), new_work(contact_tsit5.WORK)
    m = len(ics)
    out = (np.zeros(m, np.int64), np.zeros(m, np.int64), np.zeros(m, np.int64))
    kernels = {}
    t0 = time.perf_counter()
    for name in names:
        factory, over = table[name]
        tag = "split_" + name.replace(" ", "_").replace("-", "_")
        kernels[name] = summary_roll(build_step(factory, tag, **over), tag)
    hashes = {}
    for name in names:  # compile (numba compiles on the first call) and check the trajectory
        _all(kernels[name], kin.ics, kin.off0, kin.params, S, Wk, *out)
        hashes[name] = hashlib.sha256(b"".join(a.tobytes() for a in out)).hexdigest()[:12]
    print(f"compiled {len(names)} variants in {time.perf_counter() - t0:.0f} s", flush=True)
    # the plain scheme runs twice a round: the gap between its two best times is the noise floor
    rounds = names + ["plain again"]
    kernels["plain again"] = kernels["plain"]
    best = dict.fromkeys(rounds, np.inf)
    for _ in range(max(1, args.repeat)):
        for name in rounds:
            c0 = time.process_time()
            _all(kernels[name], kin.ics, kin.off0, kin.params, S, Wk, *out)
            best[name] = min(best[name], (time.process_time() - c0) / m * 1e3)
    attempts = macro = 0.0
    for ic in ics:
        r = simulate(ic, config=cfg)
        attempts += sum(r.substeps.values())
        macro += r.steps
    attempts /= m
    macro /= m
    base = best["plain"]
    tol = tol_text({"tol": cfg.numerics.tol, "tol_growth": cfg.numerics.tol_growth})
    print(f"contact-tsit5 on {args.preset}, tol {tol}, {m} zoom-out ICs, 1 thread, CPU ms per throw "
          f"(best of {args.repeat}, interleaved); {attempts:.0f} sub-step attempts and {macro:.0f} steps per throw")
    noise = abs(best["plain again"] - base)
    print(f"  {'plain':<16} {base:7.3f} ms/throw; run again {best['plain again']:.3f} (noise floor {noise:.3f} ms/throw)")
    print(f"  {'part':<16} {'ms/throw':>8} {'share':>7} {'ns/attempt':>11} {'ns/step':>8}  trajectory")
    for name in names[1:]:
        d = best[name] - base
        same = "same" if hashes[name] == hashes["plain"] else "CHANGED (not a valid split)"
        print(f"  {name:<16} {d:8.3f} {d / base * 100:6.1f}% {d * 1e6 / attempts:11.0f} {d * 1e6 / macro:8.0f}  {same}")


if __name__ == "__main__":
    main()
