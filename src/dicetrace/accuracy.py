"""Work-precision study of the integrators, and the map of their stable steps.

``study(...)`` (``dicetrace accuracy``) runs, for each preset × integrator ×
dt, a seeded uniform sample of ICs from a named window of the seed slice and
measures against a converged reference:

- **outcome agreement**: fraction of ICs whose outcome equals the
  reference's (a run that does not settle disagrees);
- the **chaos floor**: the agreement of the reference itself when every IC
  is perturbed by a relative 1e-12, 1e-9 and 1e-6 (IC + δ·|IC|·ξ, ξ a seeded
  random unit vector in the 6-D IC space): the best any method can do;
- **first-impact trajectory error**: largest node-position error (cm) 20 ms
  after the reference's first contact (median over a subsample of ICs);
- **settle-time bias** (s) and **contact-count bias** (contact-set changes)
  over the ICs where both runs settled;
- **free-flight energy drift**: |ΔE| / (E0 − E_rest) from the throw to the
  step before the first contact, E with the dynamics' inertia (median);
- **blow-ups** (status ``blow_up`` or ``non_finite``) and time caps;
- **CPU time per IC** (ms): process CPU time of ``simulate_batch`` on one
  numba thread after a warm-up (compilation excluded).

Fitted convergence orders: the slope of log(first-impact error) against
log(dt) over the points where the error converges (monotone, above
rounding).  The reference is stated with its evidence of convergence: the
same method at half its step agrees with it on (almost) every IC, closer
than the 1e-9 chaos floor allows a perturbation to.

``stability_map(...)`` (``dicetrace stability``) finds, for each integrator,
the largest stable dt across stiffnesses k and an extreme corpus of ICs, and
compares it with the linear bound ω·dt < 2 (semi-implicit Euler, Verlet) or
2√2 (RK4) and with ``dt = "auto"``.

Outputs: CSVs, PNG plots (matplotlib, imported lazily) and a Markdown
summary; see :func:`write_study` and :func:`write_stability`.
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from dicetrace.ics import SEED_SLICE, WINDOWS, Sample, get_window
from dicetrace.params import (
    INTEGRATORS,
    Config,
    convert_l,
    Numerics,
    auto_dt,
    get_preset,
    impact_speed_cm_s,
    make_config,
)

PRESETS = ("seed", "physical")
PERTURBATIONS = (1e-12, 1e-9, 1e-6)
DEFAULT_WINDOW = "zoom-out"
DEFAULT_N = 300
QUICK_N = 12
#: Time cap of the study's runs, s (every reference run settles well before).
T_MAX_S = 20.0
#: First-impact horizon: this long after the reference's first contact, rounded
#: up to a multiple of HORIZON_GRID_S (every dt of the grids divides it), s.
FIRST_IMPACT_AFTER_S = 0.02
HORIZON_GRID_S = 0.008
#: ICs of the trajectory subsample (first-impact error, energy drift).
N_TRAJ = 24
QUICK_N_TRAJ = 4

#: Steps studied per integrator, s.  Every one divides HORIZON_GRID_S.
#: (The steps and tolerances studied are each integrator's ``IntegratorSpec.study_dt_s``,
#: ``quick_dt_s``, ``study_tol`` and ``quick_tol``; every step divides HORIZON_GRID_S.)
DT_GRID: dict[str, tuple[float, ...]] = {n: s.study_dt_s for n, s in INTEGRATORS.items()}
QUICK_DT_GRID: dict[str, tuple[float, ...]] = {n: s.quick_dt_s for n, s in INTEGRATORS.items()}
TOL_GRID: dict[str, tuple[float, ...]] = {n: s.study_tol for n, s in INTEGRATORS.items() if s.adaptive}
QUICK_TOL_GRID: dict[str, tuple[float, ...]] = {n: s.quick_tol for n, s in INTEGRATORS.items() if s.adaptive}


@dataclass(frozen=True)
class Reference:
    """The converged reference: an integrator at a step, checked at half that step."""

    integrator: str = "contact-substep"
    dt_s: float = 1e-4

    @property
    def check_dt_s(self) -> float:
        return self.dt_s / 2.0


REFERENCE = Reference("contact-substep", 1e-4)
QUICK_REFERENCE = Reference("contact-substep", 2.5e-4)

#: Plot colour of each integrator (work-precision and stability plots): its spec's colour.
INTEGRATOR_COLORS = {n: s.color for n, s in INTEGRATORS.items()}

#: CSV columns of the study, in order.
STUDY_COLUMNS = (
    "preset",
    "integrator",
    "order",
    "dt_s",
    "tol",
    "n_ics",
    "cpu_ms_per_ic",
    "outcome_agreement",
    "settled_fraction",
    "settle_time_bias_s",
    "settle_time_mae_s",
    "contact_count_bias",
    "first_impact_error_cm",
    "free_flight_energy_drift",
    "blow_ups",
    "time_caps",
    "chaos_floor_1e-12",
    "chaos_floor_1e-09",
    "chaos_floor_1e-06",
    "reference_integrator",
    "reference_dt_s",
    "reference_self_agreement",
    "window",
    "seed",
)


# -- small helpers ---------------------------------------------------------------------------


@contextlib.contextmanager
def numba_threads(n: int | None):
    """Run the block with ``n`` numba threads (None: unchanged)."""
    import numba

    if n is None:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def sample_ics(window: str = DEFAULT_WINDOW, n: int = DEFAULT_N, seed: int = 0) -> np.ndarray:
    """``n`` seeded uniform ICs (program convention) from a window of the seed slice."""
    box = get_window(window, 2)
    return Sample(SEED_SLICE, box, int(n), "random", int(seed)).block(0, int(n)).ics


def perturb(ics: np.ndarray, rel: float, seed: int) -> np.ndarray:
    """IC + rel·|IC|·ξ with ξ a seeded random unit vector per IC (6-D)."""
    rng = np.random.default_rng([seed, 7919])
    xi = rng.normal(size=ics.shape)
    xi /= np.linalg.norm(xi, axis=1, keepdims=True)
    return ics + rel * np.linalg.norm(ics, axis=1, keepdims=True) * xi


def config_for(preset: str, integrator: str, dt_s: float, t_max_s: float = T_MAX_S, tol: float | None = None) -> Config:
    return make_config(preset, integrator=integrator, dt_s=dt_s, t_max_s=t_max_s, tol=tol)


@dataclass
class Runs:
    """Summaries of one configuration over the study's ICs."""

    outcome: np.ndarray
    status: np.ndarray  # names
    t_settle_s: np.ndarray
    n_changes: np.ndarray
    t_first_contact_s: np.ndarray
    cpu_ms_per_ic: float = float("nan")


def run_batch(ics_preset: np.ndarray, cfg: Config, *, threads: int | None = None, timed: bool = False) -> Runs:
    """``simulate_batch`` over ICs already in the preset's convention (timed on request)."""
    from dicetrace.simulate import simulate_batch

    cpu = float("nan")
    with numba_threads(1 if timed else threads):
        if timed:
            simulate_batch(ics_preset[:1], config=cfg)  # warm-up: compile / load the cache
            t0 = time.process_time()
            r = simulate_batch(ics_preset, config=cfg)
            cpu = (time.process_time() - t0) / len(ics_preset) * 1e3
        else:
            r = simulate_batch(ics_preset, config=cfg)
    m = len(r)
    n_changes = np.diff(r.set_offsets) - 1
    t_first = np.full(m, np.nan)
    for i in range(m):
        a, b = r.set_offsets[i], r.set_offsets[i + 1]
        if b - a > 1:
            t_first[i] = r.set_steps[a + 1] * cfg.numerics.dt_s
    return Runs(
        outcome=r.outcome.astype(int),
        status=r.status,
        t_settle_s=r.t_settle_s.astype(float),
        n_changes=n_changes.astype(int),
        t_first_contact_s=t_first,
        cpu_ms_per_ic=cpu,
    )


def agreement(a: Runs, ref: Runs) -> float:
    """Fraction of ICs with the reference's outcome (unsettled runs disagree)."""
    ok = (a.status == "settled") & (ref.status == "settled") & (a.outcome == ref.outcome)
    return float(np.mean(ok))


def first_impact_horizon(t_first_contact_s: float) -> float:
    """Horizon of the first-impact error: first contact + 20 ms, up to a multiple of HORIZON_GRID_S."""
    if not np.isfinite(t_first_contact_s):
        return float("nan")
    return math.ceil((t_first_contact_s + FIRST_IMPACT_AFTER_S) / HORIZON_GRID_S - 1e-9) * HORIZON_GRID_S


@dataclass
class Trajectory:
    """Node positions at the first-impact horizon and the free-flight energy drift of one IC."""

    node_pos: np.ndarray | None  # (8, 3) at the horizon, None if the run ended before it
    energy_drift: float


def run_trajectory(ic_kernel_conv: np.ndarray, cfg: Config, horizon_s: float) -> Trajectory:
    """Trace one IC up to ``horizon_s`` (a multiple of dt) and measure what the study needs."""
    from dicetrace.simulate import Record, simulate

    c = replace(cfg, numerics=replace(cfg.numerics, t_max_s=horizon_s))
    r = simulate(ic_kernel_conv, config=c, record=Record(states=True, energy=True))
    tr = r.trace
    z = tr.node_pos[:, :, 2]
    touched = np.nonzero((z <= 0.0).any(axis=1))[0]
    last_free = (touched[0] - 1) if len(touched) else len(z) - 1
    e = tr.energy["total"]
    e_rest = cfg.preset.e_rest
    drift = abs(e[last_free] - e[0]) / max(e[0] - e_rest, 1e-300)
    pos = None
    if r.status == "time_cap" and r.steps == c.numerics.max_steps:
        pos = tr.node_pos[-1].copy()
    return Trajectory(pos, float(drift))


def fit_order(dts, errs) -> float:
    """Slope of log(err) against log(dt) where the error converges.

    Uses the longest run of consecutive points (from the finest step up)
    whose error decreases with dt and stays above 1e-13 cm and below 0.5 cm
    (beyond that the first impact is no longer resolved).  NaN with fewer
    than 2 such points.
    """
    d = np.asarray(dts, float)
    e = np.asarray(errs, float)
    order = np.argsort(d)
    d, e = d[order], e[order]
    good = np.isfinite(e) & (e > 1e-13) & (e < 0.5)
    idx = [i for i in range(len(d)) if good[i]]
    if len(idx) < 2:
        return float("nan")
    run = [idx[0]]
    for i in idx[1:]:
        if i == run[-1] + 1 and e[i] > e[run[-1]]:
            run.append(i)
        elif len(run) < 2:
            run = [i]
        else:
            break
    if len(run) < 2:
        return float("nan")
    slope, _ = np.polyfit(np.log(d[run]), np.log(e[run]), 1)
    return float(slope)


# -- the study -------------------------------------------------------------------------------


@dataclass
class StudyResult:
    """Rows of the study (dicts with STUDY_COLUMNS), fitted orders and the reference evidence."""

    rows: list[dict]
    orders: list[dict]
    references: list[dict]
    window: str
    n: int
    seed: int
    quick: bool
    seed_cost_ms: float = float("nan")
    notes: list[str] = field(default_factory=list)
    #: seed against physical on the same throws (their converged references), when both ran
    preset_comparison: dict = field(default_factory=dict)

    def table(self):
        import pandas as pd

        return pd.DataFrame(self.rows, columns=list(STUDY_COLUMNS))


def study(
    *,
    window: str = DEFAULT_WINDOW,
    n: int | None = None,
    seed: int = 0,
    quick: bool = False,
    presets=PRESETS,
    integrators=None,
    dt_grid: dict | None = None,
    reference: Reference | None = None,
    n_traj: int | None = None,
    threads: int | None = 2,
    progress=None,
) -> StudyResult:
    """Run the work-precision study (see the module docstring).

    Parameters
    ----------
    window
        A name in ``dicetrace.ics.WINDOWS`` or ``x0,x1,y0,y1`` on the seed slice.
    n
        ICs in the sample (default 300; ``quick``: 12).
    quick
        CI size: fewer ICs, two steps per integrator, a coarser reference.
    threads
        numba threads for the untimed runs (reference, floors); timed runs use one.
    progress
        Optional callable ``progress(message)``.
    """
    say = progress or (lambda msg: None)
    n = int(n if n is not None else (QUICK_N if quick else DEFAULT_N))
    if n < 2:
        raise ValueError(f"the study needs at least 2 ICs, got n = {n}")
    integrators = tuple(integrators or INTEGRATORS)
    for name in integrators:
        if name not in INTEGRATORS:
            raise ValueError(f"unknown integrator {name!r} (choose from {', '.join(INTEGRATORS)})")
    for p in presets:
        get_preset(p)
    grid = dt_grid or (QUICK_DT_GRID if quick else DT_GRID)
    tol_grid = QUICK_TOL_GRID if quick else TOL_GRID
    ref_spec = reference or (QUICK_REFERENCE if quick else REFERENCE)
    n_traj = min(n, int(n_traj if n_traj is not None else (QUICK_N_TRAJ if quick else N_TRAJ)))
    ics_prog = sample_ics(window, n, seed)
    rows, orders, references = [], [], []
    seed_cost = float("nan")
    ref_runs = {}
    for preset in presets:
        conv = get_preset(preset).l_convention
        ics = convert_l(ics_prog, "program", conv)
        say(f"[{preset}] reference {ref_spec.integrator} dt={ref_spec.dt_s:g} s on {n} ICs")
        ref_cfg = config_for(preset, ref_spec.integrator, ref_spec.dt_s)
        ref = run_batch(ics, ref_cfg, threads=threads)
        chk = run_batch(ics, config_for(preset, ref_spec.integrator, ref_spec.check_dt_s), threads=threads)
        floors = {}
        for rel in PERTURBATIONS:
            say(f"[{preset}] chaos floor {rel:g}")
            floors[rel] = agreement(run_batch(perturb(ics, rel, seed), ref_cfg, threads=threads), ref)
        self_agree = agreement(chk, ref)
        ref_runs[preset] = ref
        # trajectory subsample: reference traces at each IC's horizon
        horizons = np.array([first_impact_horizon(t) for t in ref.t_first_contact_s[:n_traj]])
        ref_traj = [
            run_trajectory(ics[i], ref_cfg, horizons[i]) if np.isfinite(horizons[i]) else None for i in range(n_traj)
        ]
        chk_cfg = config_for(preset, ref_spec.integrator, ref_spec.check_dt_s)
        chk_err = _traj_error(ics, chk_cfg, horizons, ref_traj)[0]
        references.append(
            {
                "preset": preset,
                "integrator": ref_spec.integrator,
                "dt_s": ref_spec.dt_s,
                "check_dt_s": ref_spec.check_dt_s,
                "self_agreement": self_agree,
                "check_first_impact_error_cm": chk_err,
                "settled_fraction": float(np.mean(ref.status == "settled")),
                "mean_settle_time_s": _mean(ref.t_settle_s[ref.status == "settled"]),
                "mean_contact_changes": float(np.mean(ref.n_changes)),
                **{f"chaos_floor_{rel:.0e}": floors[rel] for rel in PERTURBATIONS},
            }
        )
        for integ in integrators:
            errs = []
            tols = tol_grid.get(integ, ())
            runs_at = [(dt, tol) for dt in grid.get(integ, ()) for tol in (tols or (None,))]
            for dt, tol in runs_at:
                say(f"[{preset}] {integ} dt={dt:g} s" + ("" if tol is None else f" tol={tol:g}"))
                cfg = config_for(preset, integ, dt, tol=tol)
                runs = run_batch(ics, cfg, timed=True)
                both = (runs.status == "settled") & (ref.status == "settled")
                t_err = runs.t_settle_s[both] - ref.t_settle_s[both]
                c_err = runs.n_changes[both] - ref.n_changes[both]
                ferr, drift = _traj_error(ics, cfg, horizons, ref_traj)
                errs.append(ferr)
                if preset == "seed" and integ == "semi-implicit-euler" and dt == 1e-3:
                    seed_cost = runs.cpu_ms_per_ic
                rows.append(
                    {
                        "preset": preset,
                        "integrator": integ,
                        "order": INTEGRATORS[integ].order,
                        "dt_s": dt,
                        "tol": float("nan") if tol is None else tol,
                        "n_ics": n,
                        "cpu_ms_per_ic": runs.cpu_ms_per_ic,
                        "outcome_agreement": agreement(runs, ref),
                        "settled_fraction": float(np.mean(runs.status == "settled")),
                        "settle_time_bias_s": float(np.mean(t_err)) if both.any() else float("nan"),
                        "settle_time_mae_s": float(np.mean(np.abs(t_err))) if both.any() else float("nan"),
                        "contact_count_bias": float(np.mean(c_err)) if both.any() else float("nan"),
                        "first_impact_error_cm": ferr,
                        "free_flight_energy_drift": drift,
                        "blow_ups": int(np.sum(np.isin(runs.status, ("blow_up", "non_finite")))),
                        "time_caps": int(np.sum(runs.status == "time_cap")),
                        "chaos_floor_1e-12": floors[1e-12],
                        "chaos_floor_1e-09": floors[1e-9],
                        "chaos_floor_1e-06": floors[1e-6],
                        "reference_integrator": ref_spec.integrator,
                        "reference_dt_s": ref_spec.dt_s,
                        "reference_self_agreement": self_agree,
                        "window": window,
                        "seed": seed,
                    }
                )
            orders.append(
                {
                    "preset": preset,
                    "integrator": integ,
                    "declared_order": INTEGRATORS[integ].order,
                    # error-controlled runs: the exponent of the error against tol at one dt
                    "fitted_order_first_impact": fit_order([t if t is not None else d for d, t in runs_at], errs)
                    if len(runs_at) >= 2
                    else float("nan"),
                    "against": "tol" if tols else "dt",
                }
            )
    notes = []
    if window not in WINDOWS:
        notes.append(f"window given as coordinates: {window}")
    comparison = compare_presets(ref_runs["seed"], ref_runs["physical"]) if {"seed", "physical"} <= set(ref_runs) else {}
    return StudyResult(rows, orders, references, window, n, seed, quick, seed_cost, notes, comparison)


def compare_presets(seed: Runs, phys: Runs) -> dict:
    """Outcomes and settle times of the two presets' references on the same throws."""
    both = (seed.status == "settled") & (phys.status == "settled")
    return {
        "same_outcome": float(np.mean(both & (seed.outcome == phys.outcome))),
        "outcome_counts_seed": {int(f): int(np.sum(seed.outcome == f)) for f in range(0, 7)},
        "outcome_counts_physical": {int(f): int(np.sum(phys.outcome == f)) for f in range(0, 7)},
        "mean_settle_time_seed_s": float(np.mean(seed.t_settle_s[both])) if both.any() else float("nan"),
        "mean_settle_time_physical_s": float(np.mean(phys.t_settle_s[both])) if both.any() else float("nan"),
        "median_settle_time_ratio": float(np.median(phys.t_settle_s[both] / seed.t_settle_s[both])) if both.any() else float("nan"),
        "mean_contact_changes_seed": float(np.mean(seed.n_changes[both])) if both.any() else float("nan"),
        "mean_contact_changes_physical": float(np.mean(phys.n_changes[both])) if both.any() else float("nan"),
        "mean_first_contact_s": _mean(seed.t_first_contact_s[np.isfinite(seed.t_first_contact_s)]),
    }


def _mean(x) -> float:
    x = np.asarray(x, float)
    return float(np.mean(x)) if x.size else float("nan")


def _traj_error(ics, cfg, horizons, ref_traj):
    """(median first-impact node error in cm, median free-flight energy drift) over the subsample."""
    errs, drifts = [], []
    for i, rt in enumerate(ref_traj):
        if rt is None:
            continue
        tr = run_trajectory(ics[i], cfg, horizons[i])
        drifts.append(tr.energy_drift)
        if tr.node_pos is None or rt.node_pos is None:
            errs.append(np.inf)  # ended (blow-up, settled) before the horizon
        else:
            errs.append(float(np.max(np.linalg.norm(tr.node_pos - rt.node_pos, axis=1))))
    med = float(np.median(errs)) if errs else float("nan")
    return med, (float(np.median(drifts)) if drifts else float("nan"))


# -- budgets and the summary ----------------------------------------------------------------------


def best_within_budget(rows: list[dict], preset: str, integrator: str, budget_ms: float) -> dict | None:
    """The most accurate run (highest agreement) of an integrator that costs ≤ budget_ms per IC."""
    cand = [
        r
        for r in rows
        if r["preset"] == preset and r["integrator"] == integrator and r["cpu_ms_per_ic"] <= budget_ms
    ]
    if not cand:
        return None
    return max(cand, key=lambda r: (r["outcome_agreement"], -r["cpu_ms_per_ic"]))


def budget_table(res: StudyResult, factors=(1.0, 10.0)) -> list[dict]:
    """For each preset × integrator × budget (factor × the seed's cost): the best run within it."""
    out = []
    base = res.seed_cost_ms
    if not np.isfinite(base):
        return out
    presets = sorted({r["preset"] for r in res.rows}, key=list(PRESETS).index)
    integs = [i for i in INTEGRATORS if any(r["integrator"] == i for r in res.rows)]
    for preset in presets:
        ref = next(x for x in res.references if x["preset"] == preset)
        for f in factors:
            for integ in integs:
                b = best_within_budget(res.rows, preset, integ, f * base)
                out.append(
                    {
                        "preset": preset,
                        "budget": f"{f:g}x seed ({f * base:.3g} ms)",
                        "integrator": integ,
                        "dt_s": b["dt_s"] if b else float("nan"),
                        "tol": b.get("tol", float("nan")) if b else float("nan"),
                        "cpu_ms_per_ic": b["cpu_ms_per_ic"] if b else float("nan"),
                        "outcome_agreement": b["outcome_agreement"] if b else float("nan"),
                        "settle_time_bias_s": b["settle_time_bias_s"] if b else float("nan"),
                        "chaos_floor_1e-12": ref["chaos_floor_1e-12"],
                        "chaos_floor_1e-09": ref["chaos_floor_1e-09"],
                    }
                )
    return out


def setting(r: dict) -> str:
    """A run's numerical setting as text: dt, and tol for the error-controlled integrator."""
    tol = r.get("tol", float("nan"))
    if tol is not None and np.isfinite(tol):
        return f"dt = {r['dt_s']:g} s, tol = {tol:g}"
    return f"dt = {r['dt_s']:g} s"


def _fmt(v, spec=".3g"):
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—"
    return format(v, spec)


def summary_markdown(res: StudyResult, command: str) -> str:
    """The study's Markdown summary (tables and the best method per budget)."""
    lines = [
        "# Work-precision study of the integrators",
        "",
        f"Command: `{command}`",
        "",
        f"ICs: {res.n} seeded uniform points (seed {res.seed}) of the `{res.window}` window of the seed slice; "
        "the `physical` preset gets the same throws (L negated into its physical convention). "
        f"Time cap {T_MAX_S:g} s. CPU time: process time of `simulate_batch` on one numba thread after warm-up.",
        "",
        "## Reference and chaos floor",
        "",
        "| preset | reference | check at dt/2: outcome agreement | check: first-impact error (cm) | "
        "floor 1e-12 | floor 1e-9 | floor 1e-6 | mean settle time (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in res.references:
        lines.append(
            f"| {r['preset']} | {r['integrator']} dt={r['dt_s']:g} s | {r['self_agreement']:.3f} | "
            f"{_fmt(r['check_first_impact_error_cm'], '.2e')} | {r['chaos_floor_1e-12']:.3f} | "
            f"{r['chaos_floor_1e-09']:.3f} | {r['chaos_floor_1e-06']:.3f} | {r['mean_settle_time_s']:.3f} |"
        )
    pc = res.preset_comparison
    if pc:
        counts = lambda d: ", ".join(f"{f}: {c}" for f, c in d.items() if f > 0 or c)  # noqa: E731
        lines += [
            "",
            "`seed` against `physical` on the same throws (their references): "
            f"same outcome on {pc['same_outcome']:.3f} of the ICs (chance would be about 1/6); "
            f"mean settle time {pc['mean_settle_time_seed_s']:.3f} s (seed) against {pc['mean_settle_time_physical_s']:.3f} s "
            f"(physical; median ratio {pc['median_settle_time_ratio']:.2f}); contact-set changes "
            f"{pc['mean_contact_changes_seed']:.1f} against {pc['mean_contact_changes_physical']:.1f}. "
            f"Faces (seed) {counts(pc['outcome_counts_seed'])}; (physical) {counts(pc['outcome_counts_physical'])}.",
        ]
    lines += [
        "",
        "The chaos floor is the outcome agreement of the reference with itself when every IC is moved by a relative "
        "δ (random direction): no method can be expected to agree better than the floor at the size of its own error. "
        "The reference counts as converged when halving its step changes fewer outcomes than a 1e-9 perturbation does.",
        "",
        "## All runs",
        "",
        "| preset | integrator | dt (s) | tol | CPU ms/IC | agreement | settle-time bias (s) | contact-count bias | "
        "first-impact error (cm) | free-flight energy drift | blow-ups | time caps |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res.rows:
        lines.append(
            f"| {r['preset']} | {r['integrator']} | {r['dt_s']:g} | {_fmt(r.get('tol'), 'g')} | {r['cpu_ms_per_ic']:.3g} | "
            f"{r['outcome_agreement']:.3f} | {_fmt(r['settle_time_bias_s'], '+.4f')} | "
            f"{_fmt(r['contact_count_bias'], '+.2f')} | {_fmt(r['first_impact_error_cm'], '.2e')} | "
            f"{_fmt(r['free_flight_energy_drift'], '.1e')} | {r['blow_ups']} | {r['time_caps']} |"
        )
    lines += ["", "## Fitted convergence orders (first-impact error against dt; for contact-adaptive against tol)", ""]
    lines += ["| preset | integrator | declared order | against | fitted exponent |", "|---|---|---|---|---|"]
    for o in res.orders:
        lines.append(
            f"| {o['preset']} | {o['integrator']} | {o['declared_order']} | {o.get('against', 'dt')} | "
            f"{_fmt(o['fitted_order_first_impact'], '.2f')} |"
        )
    bt = budget_table(res)
    if bt:
        lines += [
            "",
            f"## At the seed's cost ({res.seed_cost_ms:.3g} ms per throw: `seed`, semi-implicit Euler, dt = 1 ms) and 10×",
            "",
            "Best run of each integrator whose CPU time per IC is within the budget.",
            "",
            "| preset | budget | integrator | dt (s) | tol | CPU ms/IC | agreement | settle-time bias (s) | floor 1e-12 | floor 1e-9 |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for b in bt:
            lines.append(
                f"| {b['preset']} | {b['budget']} | {b['integrator']} | {_fmt(b['dt_s'], 'g')} | {_fmt(b['tol'], 'g')} | "
                f"{_fmt(b['cpu_ms_per_ic'], '.3g')} | {_fmt(b['outcome_agreement'], '.3f')} | "
                f"{_fmt(b['settle_time_bias_s'], '+.4f')} | {b['chaos_floor_1e-12']:.3f} | {b['chaos_floor_1e-09']:.3f} |"
            )
    lines += ["", "## Best method for a time budget", ""]
    for preset in sorted({r["preset"] for r in res.rows}, key=list(PRESETS).index):
        costs = sorted({r["cpu_ms_per_ic"] for r in res.rows if r["preset"] == preset})
        budgets = _budget_points(costs, res.seed_cost_ms)
        for bud in budgets:
            best = None
            for integ in INTEGRATORS:
                b = best_within_budget(res.rows, preset, integ, bud)
                if b and (best is None or b["outcome_agreement"] > best["outcome_agreement"]):
                    best = b
            if best is None:
                lines.append(f"- `{preset}`, {bud:.3g} ms per throw: no run fits.")
            else:
                lines.append(
                    f"- `{preset}`, {bud:.3g} ms per throw: **{best['integrator']}** at {setting(best)} "
                    f"(agreement {best['outcome_agreement']:.3f}, {best['cpu_ms_per_ic']:.3g} ms)."
                )
    for note in res.notes:
        lines += ["", note]
    return "\n".join(lines) + "\n"


def _budget_points(costs, seed_cost):
    pts = []
    if np.isfinite(seed_cost):
        pts = [seed_cost * f for f in (1.0, 10.0, 100.0)]
    elif costs:
        pts = [costs[0], costs[len(costs) // 2], costs[-1]]
    return pts


def plot_study(res: StudyResult, path) -> None:
    """Outcome agreement and first-impact error against CPU time per IC, one line per integrator."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = [p for p in PRESETS if any(r["preset"] == p for r in res.rows)]
    fig, axes = plt.subplots(len(presets), 2, figsize=(12, 4.6 * len(presets)), squeeze=False)
    colors = INTEGRATOR_COLORS
    for row, preset in enumerate(presets):
        ref = next(x for x in res.references if x["preset"] == preset)
        ax, bx = axes[row]
        for integ in INTEGRATORS:
            rr = sorted((r for r in res.rows if r["preset"] == preset and r["integrator"] == integ), key=lambda r: r["cpu_ms_per_ic"])
            if not rr:
                continue
            c = [r["cpu_ms_per_ic"] for r in rr]
            ax.plot(c, [r["outcome_agreement"] for r in rr], "o-", color=colors[integ], label=integ)
            for r in rr:
                lab = f"{r['tol']:.0e}" if np.isfinite(r.get("tol", float("nan"))) else f"{r['dt_s']:g}"
                ax.annotate(lab, (r["cpu_ms_per_ic"], r["outcome_agreement"]), fontsize=6,
                            xytext=(2, 2), textcoords="offset points", color=colors[integ])
            e = np.array([r["first_impact_error_cm"] for r in rr], float)
            e = np.where(np.isfinite(e), e, np.nan)
            bx.plot(c, e, "o-", color=colors[integ], label=integ)
        for rel, ls in zip(PERTURBATIONS, (":", "--", "-.")):
            ax.axhline(ref[f"chaos_floor_{rel:.0e}"], color="k", ls=ls, lw=1, label=f"chaos floor δ={rel:g}")
        ax.axhline(1 / 6, color="grey", lw=0.8, ls="-", alpha=0.5, label="chance (1/6)")
        for f in (1.0, 10.0):
            if np.isfinite(res.seed_cost_ms):
                ax.axvline(f * res.seed_cost_ms, color="grey", lw=0.8, ls=":")
                bx.axvline(f * res.seed_cost_ms, color="grey", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("CPU time per throw (ms, one thread)")
        ax.set_ylabel("outcome agreement with the reference")
        ax.set_title(f"{preset}: outcome agreement (labels: dt in s, or tol; dotted: seed cost, 10×)")
        ax.legend(fontsize=7, loc="upper left")
        bx.set_xscale("log")
        chk = ref["check_first_impact_error_cm"]
        if np.isfinite(chk) and chk > 0:
            bx.axhline(chk, color="k", ls="--", lw=1, label="reference vs dt/2")
        errs = [r["first_impact_error_cm"] for r in res.rows if r["preset"] == preset]
        if any(np.isfinite(e) and e > 0 for e in errs):
            bx.set_yscale("log")
        bx.set_xlabel("CPU time per throw (ms, one thread)")
        bx.set_ylabel("node-position error 20 ms after first contact (cm)")
        bx.set_title(f"{preset}: first-impact trajectory error (median)")
        bx.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_study(res: StudyResult, out_dir, command: str) -> dict:
    """Write study.csv, orders.csv, reference.csv, work_precision.png and summary.md into ``out_dir``."""
    import pandas as pd
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "csv": out / "study.csv",
        "orders": out / "orders.csv",
        "reference": out / "reference.csv",
        "png": out / "work_precision.png",
        "summary": out / "summary.md",
    }
    res.table().to_csv(paths["csv"], index=False)
    if res.preset_comparison:
        import json

        (out / "presets.json").write_text(json.dumps(res.preset_comparison, indent=1) + "\n")
        paths["presets"] = out / "presets.json"
    pd.DataFrame(res.orders).to_csv(paths["orders"], index=False)
    pd.DataFrame(res.references).to_csv(paths["reference"], index=False)
    plot_study(res, paths["png"])
    paths["summary"].write_text(summary_markdown(res, command))
    return paths


# -- stability map ---------------------------------------------------------------------------------

K_VALUES = (5e5, 5e5 * 10**0.5, 5e6, 5e6 * 10**0.5, 5e7)
QUICK_K_VALUES = (5e5, 5e7)
#: Time cap of the stability runs, s (covers the first impacts, where the speeds peak).
STABILITY_T_MAX_S = 0.5
DT_SEARCH = (1e-6, 1.6e-2)
BISECTIONS = 7


def extreme_corpus(seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """The extreme ICs (program convention) and their labels.

    |U| up to 2000 cm/s, |L| up to 5000 node-mass·cm²/s; near-vertical
    drops (flat and tilted), pure spins, grazing throws, random violent
    throws and a few ordinary seed-slice throws.
    """
    rng = np.random.default_rng([seed, 4242])
    ics, labels = [], []

    def add(u, l, label):
        ics.append(np.r_[np.asarray(u, float), np.asarray(l, float)])
        labels.append(label)

    for v in (100.0, 1000.0, 2000.0):
        add((0, 0, -v), (0, 0, 0), f"vertical drop {v:g} cm/s, flat")
    add((0, 0, -2000.0), (30.0, -20.0, 0), "vertical drop 2000 cm/s, tilted")
    for axis, name in (((0, 0, 1), "z"), ((1, 0, 0), "x"), ((1, 1, 1), "diagonal")):
        a = np.asarray(axis, float)
        add((0, 0, 0), 5000.0 * a / np.linalg.norm(a), f"pure spin |L|=5000 about {name}")
    add((2000.0, 0, 0), (0, 0, 0), "grazing 2000 cm/s")
    add((1414.0, 1414.0, -5.0), (0, 0, 500.0), "grazing 2000 cm/s, yawing")
    add((2000.0, 0, 0), (0, 5000.0, 0), "grazing 2000 cm/s, topspin 5000")
    for i in range(4):
        u = rng.normal(size=3)
        u = 2000.0 * u / np.linalg.norm(u)
        l = rng.normal(size=3)
        l = 5000.0 * l / np.linalg.norm(l)
        add(u, l, f"violent random throw {i + 1}")
    for x, y in ((1.65, 3.9), (5.0, 5.0), (50.0, 50.0)):
        add(*np.split(SEED_SLICE.ics([x, y]), 2), f"seed slice ({x:g}, {y:g})")
    return np.array(ics), labels


def corpus_stable(ics_preset: np.ndarray, cfg: Config) -> tuple[bool, int, int]:
    """(all stable, index of the first unstable IC or -1, time caps); stops at the first failure."""
    from dicetrace.simulate import simulate

    caps = 0
    for i, ic in enumerate(ics_preset):
        r = simulate(ic, config=cfg)
        if r.status in ("blow_up", "non_finite"):
            return False, i, caps
        caps += r.status == "time_cap"
    return True, -1, caps


def largest_stable_dt(ics, preset_obj, integrator, *, bisections=BISECTIONS, lo_hi=DT_SEARCH):
    """Largest dt in [lo, hi] (log bisection) at which every corpus IC is stable.

    Returns (dt_stable or 0.0 if even ``lo`` fails, dt_unstable or inf,
    index of the IC that failed at dt_unstable).  Assumes stability is
    monotone in dt (checked only at the probed steps).
    """
    lo, hi = lo_hi

    def cfg(dt):
        return Config(preset=preset_obj, numerics=Numerics(integrator=integrator, dt_s=dt, t_max_s=STABILITY_T_MAX_S))

    ok_hi, fail_hi, _ = corpus_stable(ics, cfg(hi))
    if ok_hi:
        return hi, math.inf, -1
    ok_lo, fail_lo, _ = corpus_stable(ics, cfg(lo))
    if not ok_lo:
        return 0.0, lo, fail_lo
    fail = fail_hi
    for _ in range(bisections):
        mid = math.sqrt(lo * hi)
        ok, f, _ = corpus_stable(ics, cfg(mid))
        if ok:
            lo = mid
        else:
            hi, fail = mid, f
    return lo, hi, fail


def stability_map(
    *,
    quick: bool = False,
    presets=PRESETS,
    integrators=None,
    k_values=None,
    seed: int = 0,
    bisections: int | None = None,
    progress=None,
) -> list[dict]:
    """Largest stable dt per preset × integrator × k over the extreme corpus (see the module docstring)."""
    say = progress or (lambda msg: None)
    integrators = tuple(integrators or INTEGRATORS)
    for name in integrators:
        if name not in INTEGRATORS:
            raise ValueError(f"unknown integrator {name!r} (choose from {', '.join(INTEGRATORS)})")
    k_values = tuple(k_values or (QUICK_K_VALUES if quick else K_VALUES))
    ics_prog, labels = extreme_corpus(seed)
    if quick:
        keep = [0, 2, 4, 7, 10]
        ics_prog, labels = ics_prog[keep], [labels[i] for i in keep]
    nb = int(bisections if bisections is not None else (3 if quick else BISECTIONS))
    rows = []
    for preset in presets:
        base = get_preset(preset)
        ics = convert_l(ics_prog, "program", base.l_convention)
        v_imp = impact_speed_cm_s(ics_prog, base)
        for integ in integrators:
            for k in k_values:
                p = base.with_(k=float(k))
                say(f"[{preset}] {integ} k={k:.3g}")
                with numba_threads(1):
                    dt_ok, dt_bad, fail = largest_stable_dt(ics, p, integ, bisections=nb)
                spec = INTEGRATORS[integ]
                bound = spec.stability_bound * (Numerics.substeps if spec.substepped and not spec.adaptive else 1)
                try:
                    adt = auto_dt(p, integ, v_impact_cm_s=v_imp, t_max_s=STABILITY_T_MAX_S)
                    cfg = Config(preset=p, numerics=Numerics(integrator=integ, dt_s=adt, t_max_s=STABILITY_T_MAX_S))
                    with numba_threads(1):
                        auto_ok = corpus_stable(ics, cfg)[0]
                    refusal = ""
                except ValueError as e:
                    adt, auto_ok, refusal = float("nan"), None, str(e)
                rows.append(
                    {
                        "preset": preset,
                        "integrator": integ,
                        "k": float(k),
                        "omega_rad_s": math.sqrt(k),
                        "dt_stable_s": dt_ok,
                        "dt_unstable_s": dt_bad,
                        "omega_dt_stable": math.sqrt(k) * dt_ok,
                        "linear_bound_omega_dt": bound,
                        "linear_bound_dt_s": bound / math.sqrt(k) if bound > 0 else 0.0,
                        "first_failing_ic": labels[fail] if fail >= 0 else "",
                        "auto_dt_s": adt,
                        "auto_dt_stable": auto_ok,
                        "auto_dt_refusal": refusal,
                        "impact_speed_cm_s": v_imp,
                        "n_corpus": len(ics),
                        "t_max_s": STABILITY_T_MAX_S,
                    }
                )
    return rows


STABILITY_COLUMNS = (
    "preset",
    "integrator",
    "k",
    "omega_rad_s",
    "dt_stable_s",
    "dt_unstable_s",
    "omega_dt_stable",
    "linear_bound_omega_dt",
    "linear_bound_dt_s",
    "first_failing_ic",
    "auto_dt_s",
    "auto_dt_stable",
    "auto_dt_refusal",
    "impact_speed_cm_s",
    "n_corpus",
    "t_max_s",
)


def stability_markdown(rows: list[dict], command: str) -> str:
    ics, labels = extreme_corpus()
    lines = [
        "# Stability map",
        "",
        f"Command: `{command}`",
        "",
        f"Largest dt (log bisection in [{DT_SEARCH[0]:g}, {DT_SEARCH[1]:g}] s) at which every IC of the extreme corpus "
        f"ends without a blow-up or a non-finite state within {STABILITY_T_MAX_S:g} s (the first impacts, where the "
        "speeds peak), against the linear bound on the undamped spring (ω = √k per unit mass; contact-substep: "
        "RK4's bound per sub-step, 8 sub-steps; contact-adaptive: RK4's bound on a sub-step as long as dt, though its "
        "error control shortens them), and the step `dt = \"auto\"` picks.",
        "",
        "| preset | integrator | k | ω·dt stable | stable dt (s) | unstable dt (s) | linear bound ω·dt | auto dt (s) | auto stable | first failing IC |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        auto = _fmt(r["auto_dt_s"], ".3g") if not r["auto_dt_refusal"] else "refused"
        lines.append(
            f"| {r['preset']} | {r['integrator']} | {r['k']:.3g} | {r['omega_dt_stable']:.3g} | {r['dt_stable_s']:.3g} | "
            f"{_fmt(r['dt_unstable_s'], '.3g')} | {r['linear_bound_omega_dt']:.3g} | {auto} | "
            f"{'—' if r['auto_dt_stable'] is None else ('yes' if r['auto_dt_stable'] else 'NO')} | {r['first_failing_ic']} |"
        )
    lines += ["", "Corpus (program convention):", ""]
    for lab, ic in zip(labels, ics):
        lines.append(f"- {lab}: U = ({ic[0]:g}, {ic[1]:g}, {ic[2]:g}) cm/s, L = ({ic[3]:g}, {ic[4]:g}, {ic[5]:g})")
    return "\n".join(lines) + "\n"


def plot_stability(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = [p for p in PRESETS if any(r["preset"] == p for r in rows)]
    fig, axes = plt.subplots(1, len(presets), figsize=(6.5 * len(presets), 4.6), squeeze=False)
    colors = INTEGRATOR_COLORS
    for ax, preset in zip(axes[0], presets):
        for integ in INTEGRATORS:
            rr = [r for r in rows if r["preset"] == preset and r["integrator"] == integ]
            if not rr:
                continue
            k = [r["k"] for r in rr]
            ax.plot(k, [max(r["dt_stable_s"], 1e-7) for r in rr], "o-", color=colors[integ], label=f"{integ}: largest stable dt")
            if rr[0]["linear_bound_dt_s"] > 0:
                ax.plot(k, [r["linear_bound_dt_s"] for r in rr], ":", color=colors[integ], label=f"{integ}: linear bound")
            ax.plot(k, [r["auto_dt_s"] for r in rr], "x", color=colors[integ], ms=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ground stiffness k (1/s², per unit mass)")
        ax.set_ylabel("dt (s)")
        ax.set_title(f"{preset}: stable dt over the extreme corpus (x: dt auto)")
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_stability(rows: list[dict], out_dir, command: str) -> dict:
    import pandas as pd
    from pathlib import Path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "stability.csv", "png": out / "stability.png", "summary": out / "stability.md"}
    pd.DataFrame(rows, columns=list(STABILITY_COLUMNS)).to_csv(paths["csv"], index=False)
    plot_stability(rows, paths["png"])
    paths["summary"].write_text(stability_markdown(rows, command))
    return paths
