"""Cost per throw and outcome agreement of the integrators, against the seed path, in one run.

On the accuracy study's ICs (300 seeded points of the zoom-out window; L
negated for ``physical``), for both presets:

* a converged reference, computed here (untimed): the accuracy study's
  second reference (``contact-adaptive`` at dt = 1 ms, tol = 1e-10; change
  the tolerance with ``--reference-tol``);
* timed, on one numba thread, best of ``--repeat`` runs of
  ``simulate_batch`` (the study's ``run_batch``): the program's semi-implicit Euler at dt = 1 ms (on
  ``seed``: the seed path, the unit of cost), ``contact-substep`` at dt =
  1 ms, and every error-controlled scheme of the integrator table
  (``contact-adaptive``, ``contact-dop853``, ...) at
  dt = 1 ms and each of its study tolerances within ``--tol-range``.

Each line: CPU ms per throw, its ratio to the seed path measured in this
run, the outcome agreement with the reference (an unsettled run disagrees)
and the unsettled count.  CPU time is process time (steady under load,
unlike wall time).

``--budget`` adds, under each contact scheme's line, its sub-steps per
throw by what ended them (``Roll.substeps``: the error controller, the
longest sub-step, the friction law's stability bound, the end of a step, a
contact change; then rejected and redone attempts), counted in a separate,
untimed run.  ``--v-reg`` sets ``physical``'s friction regularisation
(cm/s; the reference too); ``--set NAME=VALUE`` any other field of the
``physical`` preset (repeatable; the reference too), e.g. ``--set mu=0``
to see what the sub-steps cost without friction; ``--dt`` the step of the
contact schemes (the seed path and the reference keep 1 ms).
Each error-controlled scheme also gets a line at each tolerance of the
study that loosens over the throw (the study grids' ``study_graded``; ``tol_growth``,
docs/model.md §9; ``physical``'s default among them, marked "(default)");
``--graded RATE:TOL`` (repeatable) replaces them by tolerance TOL loosening at
RATE per second.

Usage: ``python benchmarks/bench_integrators.py [--n 300] [--repeat 3]
[--tol-range 1e-9,1e-5] [--integrators contact-adaptive,contact-dop853]
[--presets seed,physical] [--budget] [--v-reg 10] [--set mu=0] [--dt 0.001]
[--graded 10:2e-8]``.
"""

from __future__ import annotations

import argparse

import numba
import numpy as np

from dicetrace.core.state import SUBSTEP_CAUSES
from dicetrace.integrators import INTEGRATORS
from dicetrace.params import convert_l, get_preset, make_config
from dicetrace.simulate import simulate
from dicetrace.studies.study_accuracy import SECOND_REFERENCE, T_MAX_S, agreement, run_batch, sample_ics
from dicetrace.studies.study_accuracy_grids import GRIDS

PRESETS = ("seed", "physical")
SEED_PATH = ("semi-implicit-euler", 1e-3, None, 0.0)


def runs(tol_range, only, dt=1e-3, graded=None) -> list[tuple[str, float, float | None, float]]:
    """(integrator, dt, tol, tol growth) of every timed line: the seed scheme, contact-substep, each adaptive
    scheme's tolerances, then its ``graded`` (rate, tol) settings (None: the study's, ``study_graded``)."""
    lo, hi = tol_range
    out = [SEED_PATH, ("contact-substep", dt, None, 0.0)]
    for name, spec in INTEGRATORS.items():
        if spec.adaptive and (not only or name in only):
            out += [(name, dt, tol, 0.0) for tol in GRIDS[name].study_tol if lo <= tol <= hi]
            out += [(name, dt, tol, rate) for rate, tol in (GRIDS[name].study_graded if graded is None else graded)]
    return [r for r in out if not only or r[0] in only or r == SEED_PATH]


def graded_settings(items, ap) -> list[tuple[float, float]]:
    """(rate, tol) of each ``--graded RATE:TOL`` (a bad one: exit 2)."""
    out = []
    for item in items:
        rate, sep, tol = item.partition(":")
        try:
            if not sep:
                raise ValueError("expected RATE:TOL")
            setting = (float(rate), float(tol))
            make_config("physical", tol=setting[1], tol_growth=setting[0])
        except ValueError as exc:
            ap.error(f"--graded {item!r}: {exc}")
        out.append(setting)
    return out


def budget(ics, cfg) -> dict[str, float]:
    """Mean sub-steps per throw by cause (``Roll.substeps``) over ``ics``."""
    total = dict.fromkeys(SUBSTEP_CAUSES, 0)
    for ic in ics:
        for cause, count in simulate(ic, config=cfg).substeps.items():
            total[cause] += count
    return {cause: count / len(ics) for cause, count in total.items()}


def physical_fields(args, ap) -> dict[str, float]:
    """The ``physical`` preset's overridden fields from ``--v-reg`` and ``--set NAME=VALUE`` (bad ones: exit 2)."""
    extra = {} if args.v_reg is None else {"v_reg_cm_s": args.v_reg}
    for item in args.set:
        name, sep, value = item.partition("=")
        if not sep:
            ap.error(f"--set {item!r}: expected NAME=VALUE")
        try:
            extra[name.strip()] = float(value)
        except ValueError:
            ap.error(f"--set {item!r}: the value is not a number")
    try:
        make_config("physical", **extra)
    except (TypeError, ValueError) as exc:
        ap.error(f"--set: {exc}")
    return extra


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--reference-tol", type=float, default=SECOND_REFERENCE.tol)
    ap.add_argument("--tol-range", default="1e-9,1e-5", help="lo,hi: the adaptive schemes' study tolerances within it")
    ap.add_argument("--integrators", default="", help="comma-separated: only these (the seed path always runs)")
    ap.add_argument("--presets", default=",".join(PRESETS), help="comma-separated presets, in this order")
    ap.add_argument("--budget", action="store_true", help="print each contact scheme's sub-steps per throw by cause")
    ap.add_argument("--v-reg", type=float, default=None, help="physical's v_reg_cm_s (default: the preset's)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="another field of the physical preset, e.g. mu=0 (repeatable)")
    ap.add_argument("--dt", type=float, default=1e-3, help="the contact schemes' step, s (default 0.001)")
    ap.add_argument("--graded", action="append", default=[], metavar="RATE:TOL",
                    help="also each error-controlled scheme at TOL loosening at RATE /s (tol_growth; repeatable; "
                         "default: each scheme's study_graded, physical's default among them)")
    args = ap.parse_args()
    extra_physical = physical_fields(args, ap)
    graded = graded_settings(args.graded, ap) or None
    tol_range = tuple(float(v) for v in args.tol_range.split(","))
    only = {v.strip() for v in args.integrators.split(",") if v.strip()}
    numba.set_num_threads(1)
    ics_prog = sample_ics(n=args.n)
    ref_name, ref_dt = SECOND_REFERENCE.integrator, SECOND_REFERENCE.dt_s
    print(f"{args.n} zoom-out ICs, 1 thread, CPU ms per throw (best of {args.repeat}); agreement with "
          f"{ref_name} dt={ref_dt:g} s tol={args.reference_tol:g} (computed here)")
    if extra_physical:
        print("physical with " + ", ".join(f"{k} = {v:g}" for k, v in extra_physical.items()))
    seed_ms = None
    lines = runs(tol_range, only, args.dt, graded)
    for preset in args.presets.split(","):
        extra = extra_physical if preset == "physical" else {}
        ics = convert_l(ics_prog, "program", get_preset(preset).l_convention)
        ref_cfg = make_config(preset, integrator=ref_name, dt_s=ref_dt, t_max_s=T_MAX_S, tol=args.reference_tol, **extra)
        ref = run_batch(ics, ref_cfg)
        default = make_config(preset, **extra).numerics
        for integ, dt, tol, growth in lines:
            cfg = make_config(preset, integrator=integ, dt_s=dt, t_max_s=T_MAX_S, tol=tol,
                              tol_growth=growth or None, **extra)
            r = run_batch(ics, cfg, timed=True, repeat=args.repeat)
            ms = r.cpu_ms_per_ic
            if preset == "seed" and (integ, dt, tol, growth) == SEED_PATH:
                seed_ms = ms
            settled = r.settled
            agree = agreement(r, ref)
            label = f"{integ} dt={dt:g}" + ("" if tol is None else f" tol={tol:g}") + (f" +{growth:g}/s" if growth else "")
            if (integ, dt, tol, growth) == (default.integrator, default.dt_s, default.tol, default.tol_growth):
                label += " (default)"
            ratio = f"{ms / seed_ms:7.3g}x" if seed_ms else "       "
            print(f"  {preset:<9} {label:<50} {ms:8.3f} ms/throw {ratio} seed   agreement {agree:.3f}   "
                  f"unsettled {int(np.sum(~settled))}", flush=True)
            if args.budget and INTEGRATORS[integ].substepped:
                b = budget(ics, cfg)
                accepted = sum(b[c] for c in SUBSTEP_CAUSES[:5])
                parts = "  ".join(f"{c} {b[c]:.0f}" for c in SUBSTEP_CAUSES)
                print(f"  {'':<9}   sub-steps/throw {accepted:.0f}: {parts}", flush=True)


if __name__ == "__main__":
    main()
