"""Study friction: how near to Coulomb the physical die's friction can go: the regularisation study.

The ``physical`` preset regularises its per-node friction,
F_xy = −μ·P·u_xy / √(|u_xy|² + v_reg²), at ``v_reg_cm_s`` = 10 cm/s: Coulomb's
law above a few v_reg, a viscous law below.  A real die sticks at far lower
slip speeds.  The smaller v_reg, the stiffer the law (its rate μ·P / (m·v_reg)
reaches ~10⁴ /s at the peak of an impact for v_reg = 10 cm/s), and the more a
converged throw costs.

For each v_reg (default 10, 3, 1, 0.3 cm/s) the study runs the accuracy
study's ICs (the zoom-out window of the seed slice, L negated into the
physical convention) with ``contact-dop853`` at a ladder of tolerances and
with ``contact-adaptive`` (an independent code path) at the tightest one, and
reports for each run: CPU ms per throw (one thread), its outcome agreement
with the tightest DOP853 run (Wilson interval), the face counts, the mean
settle time and the runs that did not settle.  A v_reg counts as converged
when the two tightest DOP853 runs agree on ≥ 0.97 of the throws and the
independent run on ≥ 0.93; its cost to converge is that of the cheapest
DOP853 tolerance that agrees with the tightest on ≥ 0.93.  The outcome
distributions of each v_reg are compared with v_reg = 10 cm/s (χ² test on the
face counts of the tightest runs) and so are the settle times.

Whether an implicit treatment of the friction makes a smaller v_reg
affordable was measured by this study with the linearly implicit
``contact-rosenbrock`` (since removed): it cost more than DOP853 at equal
agreement at every v_reg (:data:`IMPLICIT_RESULT`, written into ``v_reg.md``).

Run it with ``dicetrace analyze friction --out analysis/accuracy`` (it writes
``v_reg.csv`` and ``v_reg.md``; ``--quick`` for a small check, into
``./dicetrace-results/friction`` by default).  The committed ``v_reg.md`` was
written when the study was started as ``python -m dicetrace.studies.friction_reg``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from dicetrace.analysis.agreement import agreement, counts_chi2_p
from dicetrace.compile_clock import CompileClock, time_text
from dicetrace.params import make_config
from dicetrace.studies.outputs import write_text, written
from dicetrace.studies.study_accuracy import T_MAX_S, run_batch, sample_ics

V_REGS = (10.0, 3.0, 1.0, 0.3)
TOLS = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11)
QUICK = dict(n=8, v_regs=(10.0, 3.0), tols=(1e-6, 1e-7))
#: What this study measured of the linearly implicit ``contact-rosenbrock`` (ROS34PW2, removed after
#: it; the run committed in analysis/accuracy/v_reg.md before its removal, figures from there).
IMPLICIT_RESULT = (
    "Why no implicit scheme: this study also ran the linearly implicit `contact-rosenbrock` (ROS34PW2, "
    "whose sub-steps no friction bound limits) at tol 1e-6 … 1e-9, and it cost more than `contact-dop853` "
    "at equal agreement at every v_reg (one run on 300 throws, before the scheme was removed): at 10 cm/s "
    "0.947 agreement at 9.56 ms per throw against DOP853's 0.937 at 0.62 ms; at 3 cm/s 0.963 at 79.7 ms "
    "against 0.967 at 3 ms; at 1 cm/s 0.863 at 86.8 ms against the same 0.863 at 6.49 ms; at 0.3 cm/s "
    "0.800 at 115 ms against 0.843 at 12.9 ms. Its sub-steps were limited by accuracy, not by the friction "
    "law's stability bound: the stick–slip transitions and the die's ringing on its spring are physics "
    "the outcome depends on, to be followed, not damped (analysis/accuracy/TUNING.md §3 and §12)."
)
#: Agreement of the two tightest runs (and the independent one) that makes a v_reg converged.
CONVERGED_SELF = 0.97
CONVERGED_TARGET = 0.93


def _run(ics, v_reg: float, integrator: str, tol: float):
    cfg = make_config("physical", integrator=integrator, dt_s=1e-3, t_max_s=T_MAX_S, tol=tol, v_reg_cm_s=v_reg)
    return run_batch(ics, cfg, timed=True)


def study(n: int = 300, v_regs=V_REGS, tols=TOLS, say=print) -> list[dict]:
    """Rows of the study, one per (v_reg, integrator, tol); see the module docstring."""
    ics = sample_ics(n=n).copy()
    ics[:, 3:] *= -1.0  # physical convention
    rows = []
    for v in v_regs:
        runs = {}
        for tol in tols:
            t0 = time.perf_counter()
            with CompileClock() as clock:  # a first run's compiling told apart from the throws' time
                runs[("contact-dop853", tol)] = _run(ics, v, "contact-dop853", tol)
            say(f"v_reg {v:g}: contact-dop853 tol {tol:g} ({time_text(time.perf_counter() - t0, clock.seconds, '.0f')})")
        runs[("contact-adaptive", tols[-1])] = _run(ics, v, "contact-adaptive", tols[-1])
        say(f"v_reg {v:g}: contact-adaptive tol {tols[-1]:g}")
        ref = runs[("contact-dop853", tols[-1])]
        for (integ, tol), r in runs.items():
            # over every throw, a throw that did not settle agreeing with nothing
            a = agreement(np.where(r.settled, r.outcome, -1), np.where(ref.settled, ref.outcome, -2))
            settled = r.settled
            rows.append({
                "v_reg_cm_s": v, "integrator": integ, "tol": tol, "n": n,
                "cpu_ms_per_throw": r.cpu_ms_per_ic,
                "agreement_with_tightest": a.fraction,
                "agreement_ci_low": a.ci[0], "agreement_ci_high": a.ci[1],
                "unsettled": int(np.sum(~settled)),
                "mean_settle_time_s": float(np.mean(r.t_settle_s[settled])) if settled.any() else float("nan"),
                **{f"face_{f}": int(np.sum(r.outcome[settled] == f)) for f in range(1, 7)},
            })
    return rows


def summarise(rows: list[dict]) -> list[dict]:
    """Per v_reg: converged or not, cost to converge, face counts and settle time against v_reg = 10."""
    out = []
    by_v = {}
    for r in rows:
        by_v.setdefault(r["v_reg_cm_s"], []).append(r)
    base = None
    for v, rs in by_v.items():
        dop = [r for r in rs if r["integrator"] == "contact-dop853"]
        tight, second = dop[-1], dop[-2]
        indep = next(r for r in rs if r["integrator"] == "contact-adaptive")
        converged = second["agreement_with_tightest"] >= CONVERGED_SELF and indep["agreement_with_tightest"] >= CONVERGED_TARGET
        cheapest = next((r for r in dop if r["agreement_with_tightest"] >= CONVERGED_TARGET), tight)
        faces = np.array([tight[f"face_{f}"] for f in range(1, 7)])
        if base is None:
            base = (faces, tight["mean_settle_time_s"])
            p = float("nan")
        else:
            p = counts_chi2_p(base[0], faces)
        out.append({
            "v_reg_cm_s": v, "converged": bool(converged),
            "self_agreement": second["agreement_with_tightest"], "independent_agreement": indep["agreement_with_tightest"],
            "cost_to_converge_ms": cheapest["cpu_ms_per_throw"] if converged else float("nan"),
            "cheapest_tol": cheapest["tol"] if converged else float("nan"),
            "tightest_ms": tight["cpu_ms_per_throw"],
            "faces": faces.tolist(), "chi2_p_vs_first": p,
            "mean_settle_time_s": tight["mean_settle_time_s"],
        })
    return out


def render(rows: list[dict], summary: list[dict], out: Path, command: str, wall_s: float) -> dict[str, Path]:
    """``v_reg.csv`` (every run) and ``v_reg.md`` (the tables and the answer) in ``out``; their paths."""
    out.mkdir(parents=True, exist_ok=True)
    with written(out / "v_reg.csv", "table") as tmp:
        pd.DataFrame(rows).to_csv(tmp, index=False)
    n = rows[0]["n"]
    lines = [
        "# Friction regularisation: how near to Coulomb the `physical` die can go",
        "",
        f"Command: `{command}` ({wall_s:.0f} s wall on this machine). ICs: {n} seeded points of the zoom-out "
        "window (the accuracy study's), L negated into the physical convention. Integrators: "
        "`contact-dop853` at a ladder of tolerances; `contact-adaptive` at the tightest as an independent "
        "check. Agreement: outcome agreement with the tightest DOP853 run of the same v_reg (95 % Wilson interval).",
        "",
        "| v_reg (cm/s) | integrator | tol | CPU ms/throw | agreement with tightest | 95 % CI | unsettled | mean settle time (s) | faces 1–6 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        faces = " ".join(str(r[f"face_{f}"]) for f in range(1, 7))
        lines.append(
            f"| {r['v_reg_cm_s']:g} | {r['integrator']} | {r['tol']:g} | {r['cpu_ms_per_throw']:.3g} | "
            f"{r['agreement_with_tightest']:.3f} | {r['agreement_ci_low']:.3f}–{r['agreement_ci_high']:.3f} | "
            f"{r['unsettled']} | {r['mean_settle_time_s']:.3f} | {faces} |"
        )
    lines += [
        "",
        f"## Per v_reg (converged: the two tightest DOP853 runs agree on ≥ {CONVERGED_SELF} and the independent run on ≥ {CONVERGED_TARGET})",
        "",
        "| v_reg (cm/s) | converged | self agreement | independent agreement | cost to converge (ms/throw) | tightest run (ms/throw) | faces 1–6 | χ² p against the first | mean settle time (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summary:
        cost = "—" if not s["converged"] else f"{s['cost_to_converge_ms']:.3g} (tol {s['cheapest_tol']:g})"
        p = "—" if np.isnan(s["chi2_p_vs_first"]) else f"{s['chi2_p_vs_first']:.2g}"
        lines.append(
            f"| {s['v_reg_cm_s']:g} | {'yes' if s['converged'] else 'no'} | {s['self_agreement']:.3f} | "
            f"{s['independent_agreement']:.3f} | {cost} | {s['tightest_ms']:.3g} | {' '.join(map(str, s['faces']))} | "
            f"{p} | {s['mean_settle_time_s']:.3f} |"
        )
    lines += ["", IMPLICIT_RESULT]
    write_text(out / "v_reg.md", "\n".join(lines) + "\n", "summary")
    return {"csv": out / "v_reg.csv", "summary": out / "v_reg.md"}
