"""What limits ``contact-tsit5``'s sub-steps: the friction law's relaxation or the contact spring, and where attempts are rejected.

The driver (``contact_driver.make_drive``) counts its sub-steps by what
ended them (``Roll.substeps``).  That says an accepted sub-step was error-limited,
not which part of the motion the error came from.  This script runs an
instrumented copy of the driver (lines added to the source of ``make_drive``,
as ``bench_cost_split.py`` does; the trajectory is unchanged) on the accuracy
study's zoom-out ICs and prints:

* the error- and friction-limited sub-steps by λ_f·h, with λ_f the friction
  law's stiffness bound that the driver computes at the sub-step's start
  (``contact_driver.friction_rate``), and by ω·h with ω = √k the contact
  spring's frequency per node mass.  Where λ_f·h is near 1 while ω·h ≪ 1 the
  step follows the regularised friction's relaxation, not the spring;
* the rejected attempts by what came before them (an entry or exit cut, an
  impact's first sub-step, a rejection, a friction-limited sub-step, or
  none of these), against the accepted sub-steps in the same situation.

The counters live in a field this script adds to a copy of contact-tsit5's
work record (``COUNTED``: its fields, then ``limits``), which the instrumented
driver runs in; the plain driver runs in the scheme's own.  Compiles two
variants, the plain driver and the counted one (about a minute each, nothing
cached).

Usage: ``python benchmarks/bench_step_limits.py [--n 300] [--preset physical] [--tol 1e-7]``
(default: the preset's tolerance schedule).
"""

from __future__ import annotations

import argparse
import hashlib

import numba
import numpy as np

from bench_cost_split import DRIVE, _all, _edited, _jit_inline, build_step, summary_roll
from dicetrace.core.contact_driver import first_crossing, make_drive
from dicetrace.core.schemes import contact_tsit5
from dicetrace.core.state import SUBSTEP_CAUSES, new_states, new_work
from dicetrace.params import convert_l, make_config
from dicetrace.studies.study_accuracy import T_MAX_S, sample_ics
from dicetrace.studies.text import tol_text

#: Bucket edges of λ_f·h and of ω·h.
LAM_EDGES = (0.25, 0.5, 1.0, 2.0)
OMEGA_EDGES = (0.1, 0.3, 1.0)
#: What came before a sub-step attempt (a row of the counters).
CONTEXTS = ("none of these", "an entry cut", "an exit cut", "an impact's start", "a rejection",
            "a friction-limited sub-step")
#: Rows of the counters (``COUNTED.limits``).
ROW_LAM = 0  # + cause (error 0, friction 2): rows 0 and 2
ROW_OMEGA = 3  # + cause: rows 3 and 5
ROW_REJECTED = 6
ROW_ACCEPTED = 7
#: The counters' shape: a row each, a column per bucket or per context.
LIMITS_SHAPE = (ROW_ACCEPTED + 1, max(len(CONTEXTS), len(LAM_EDGES) + 1, len(OMEGA_EDGES) + 1))
#: contact-tsit5's work record with the counters added (the driver reads every other field by name).
WORK = contact_tsit5.WORK
COUNTED = np.dtype(
    {"names": [*WORK.names, "limits"],
     "formats": [WORK.fields[n][0] for n in WORK.names] + [np.dtype((np.float64, LIMITS_SHAPE))]},
    align=True,
)


def counted_work() -> np.ndarray:
    """A (1,) ``COUNTED`` array: zeros, as ``new_work`` makes the scheme's own."""
    return np.zeros(1, COUNTED)


def _bucket(name: str, edges) -> str:
    lines = [f"            {name} = 0\n"]
    for i, e in enumerate(edges):
        lines.append(f"            if x > {e!r}:\n                {name} = {i + 1}\n")
    return "".join(lines)


def _ranges(edges) -> list[str]:
    """Column labels of the buckets cut at ``edges``: "≤ a", "a–b", ..., "> z"."""
    return [f"≤ {edges[0]:g}"] + [f"{a:g}–{b:g}" for a, b in zip(edges, edges[1:])] + [f"> {edges[-1]:g}"]


def _indented(text: str) -> str:
    """Lines of ``drive`` as they stand in ``make_drive``: each indented by ``DRIVE`` more."""
    return "".join(DRIVE + line if line.strip() else line for line in text.splitlines(keepends=True))


def instrumented_drive():
    """``make_drive`` with the counters added to its ``drive`` (see the module docstring), named ``make_drive_limits``.

    Whether a cut is an entry is read off the crossing locator: an edited copy
    of ``first_crossing`` that also returns whether its first crossing's node
    started above the ground, put in the edited driver's globals.
    """
    crossing = _edited(
        first_crossing, "first_crossing_entry",
        "    cut = 2.0\n", "    cut = 2.0\n    entry = False\n",
        "                cut = th\n", "                cut = th\n                entry = zs > 0.0\n",
        "    return cut\n", "    return cut, entry\n",
        "@jit(", "@_jit_inline(", env={"_jit_inline": _jit_inline})
    edits = [
        ("    nsub = 0\n", "    nsub = 0\n    ctx = 0\n    centry = False\n"),
        ("                entering = True\n", "                entering = True\n                ctx = 3\n"),
        ("        cut = first_crossing(", "        cut, centry = first_crossing_entry("),
        ("                nsub += 1\n                continue",
         f"                wk.limits[{ROW_REJECTED}, ctx] += 1.0\n                ctx = 4\n"
         "                nsub += 1\n                continue"),
        ("        st.substeps[cause] += 1\n",
         "        st.substeps[cause] += 1\n"
         f"        wk.limits[{ROW_ACCEPTED}, ctx] += 1.0\n"
         "        if cause == CAUSE_ERROR or cause == CAUSE_FRICTION:\n"
         "            x = lam * hs\n" + _bucket("b", LAM_EDGES)
         + f"            wk.limits[{ROW_LAM} + cause, b] += 1.0\n"
         "            x = hs * math.sqrt(kp.k)\n" + _bucket("c", OMEGA_EDGES)
         + f"            wk.limits[{ROW_OMEGA} + cause, c] += 1.0\n"
         "        ctx = 0\n"
         "        if cause == CAUSE_CUT:\n            ctx = 1 if centry else 2\n"
         "        elif cause == CAUSE_FRICTION:\n            ctx = 5\n"),
    ]
    return _edited(make_drive, "make_drive_limits", *(_indented(text) for pair in edits for text in pair),
                   env={"first_crossing_entry": crossing})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--preset", default="physical")
    ap.add_argument("--tol", type=float, default=None, help="contact-tsit5's tolerance (default: the preset's)")
    args = ap.parse_args()
    try:
        cfg = make_config(args.preset, integrator="contact-tsit5", t_max_s=T_MAX_S, tol=args.tol)
    except (TypeError, ValueError) as exc:
        ap.error(str(exc))
    if args.n < 1:
        ap.error(f"--n must be at least 1, got {args.n}")
    numba.set_num_threads(1)
    ics = convert_l(sample_ics(n=args.n), "program", cfg.preset.l_convention)
    kin = cfg.kernel_inputs(ics)
    m = len(ics)
    kernels = {}
    for name, factory in (("plain", make_drive), ("counted", instrumented_drive())):
        tag = f"limits_{name}"
        kernels[name] = summary_roll(build_step(factory, tag), tag)
    out = (np.zeros(m, np.int64), np.zeros(m, np.int64), np.zeros(m, np.int64))
    _all(kernels["plain"], kin.ics, kin.off0, kin.params, new_states(1), new_work(WORK), *out)
    plain = hashlib.sha256(b"".join(a.tobytes() for a in out)).hexdigest()
    S, Wk = new_states(1), counted_work()
    counts = np.zeros(LIMITS_SHAPE)
    causes = np.zeros(len(SUBSTEP_CAUSES))
    for i in range(m):  # one IC at a time: the counters are per throw
        Wk[0]["limits"][:] = 0.0
        one = tuple(a[i : i + 1] for a in out)
        _all(kernels["counted"], kin.ics[i : i + 1], kin.off0, kin.params, S, Wk, *one)
        counts += Wk[0]["limits"]
        causes += S[0]["substeps"]
    counted = hashlib.sha256(b"".join(a.tobytes() for a in out)).hexdigest()
    counts /= m
    causes /= m
    setting = tol_text({"tol": cfg.numerics.tol, "tol_growth": cfg.numerics.tol_growth})
    print(f"contact-tsit5 on {args.preset}, tol {setting}, {m} zoom-out ICs; per throw: "
          + ", ".join(f"{c} {v:.0f}" for c, v in zip(SUBSTEP_CAUSES, causes)))
    if counted != plain:
        print("  the counted driver CHANGED the trajectory: the figures below are not the scheme's")
    lam_cols = _ranges(LAM_EDGES)
    om_cols = _ranges(OMEGA_EDGES)
    err = SUBSTEP_CAUSES.index("error")
    fri = SUBSTEP_CAUSES.index("friction")
    print("  sub-steps by λ_f·h (the friction law's stiffness bound times the sub-step):")
    print(f"    {'':18s}" + "".join(f"{c:>9s}" for c in lam_cols))
    for label, cause in (("error-limited", err), ("friction-limited", fri)):
        print(f"    {label:18s}" + "".join(f"{v:9.1f}" for v in counts[ROW_LAM + cause, : len(lam_cols)]))
    print("  sub-steps by ω·h (ω = √k, the contact spring per node mass):")
    print(f"    {'':18s}" + "".join(f"{c:>9s}" for c in om_cols))
    for label, cause in (("error-limited", err), ("friction-limited", fri)):
        print(f"    {label:18s}" + "".join(f"{v:9.1f}" for v in counts[ROW_OMEGA + cause, : len(om_cols)]))
    print("  attempts by what came before them:")
    print(f"    {'after':30s}{'rejected':>9s}{'accepted':>9s}")
    for j, c in enumerate(CONTEXTS):
        print(f"    {c:30s}{counts[ROW_REJECTED, j]:9.1f}{counts[ROW_ACCEPTED, j]:9.1f}")


if __name__ == "__main__":
    main()
