"""Study accuracy: the work-precision study of the integrators.

Its computation (``dicetrace analyze accuracy``): :func:`study` runs, for
each preset × integrator × step (× tolerance for an error-controlled
integrator; the steps and tolerances are the integrator's row of the study's
grids, :mod:`dicetrace.studies.study_accuracy_grids`), a seeded uniform sample
of ICs from a named window of the seed slice and measures against a converged
reference:

- **outcome agreement**: fraction of ICs whose outcome equals the
  reference's (a run that does not settle disagrees);
- the **chaos floor**: the agreement of the reference itself when every IC
  is perturbed by a relative 1e-12, 1e-9 and 1e-6 (IC + δ·|IC|·ξ, ξ a seeded
  random unit vector in the 6-D IC space): the best any method can do;
- each setting's **own numerical floor**: how many of ``FLOOR_N`` ICs of
  the resolved ``home`` window change outcome (or status) when moved by a
  relative 1e-12 (:func:`perturb`), run by that very setting.  The model is
  continuous there; a scheme need not be (step-size decisions, contact
  events), and a bisection to 1e-12 with a scheme whose floor is not 0
  measures the scheme;
- **first-impact trajectory error**: largest node-position error (cm) 20 ms
  after the reference's first contact (median over a subsample of ICs);
- **settle-time bias** (s) and **contact-count bias** (contact-set changes)
  over the ICs where both runs settled;
- **free-flight energy drift**: |ΔE| / (E0 − E_rest) from the throw to the
  step before the first contact, E with the dynamics' inertia (median);
- **blow-ups** (a failed :class:`~dicetrace.Status`) and time caps;
- **CPU time per IC** (ms): process CPU time of ``simulate_batch`` on one
  numba thread after a warm-up (compilation excluded), best of
  ``TIMING_REPEAT`` runs.

Fitted convergence orders: the slope of log(first-impact error) against
log(dt) over the points where the error converges (monotone, above
rounding).  The reference is stated with its evidence of convergence: the
same method at half its step agrees with it on (almost) every IC, closer
than the 1e-9 chaos floor allows a perturbation to, and a second reference
from a different integrator (``SECOND_REFERENCE``) agrees with it (the
fraction and its Wilson interval).

It returns a :class:`StudyResult`; :mod:`dicetrace.studies.study_accuracy_render`
writes it (CSV, plot, Markdown).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from dicetrace import memory  # memory.available_memory is looked up at each call (tests patch it)
from dicetrace.analysis.agreement import agreement as wilson_agreement
from dicetrace.analysis.agreement import compare_presets, settled_agreement
from dicetrace.analysis.scaling import convergence_order
from dicetrace.ics import SEED_SLICE, Sample
from dicetrace.params import INTEGRATORS, Config, convert_l, get_preset, make_config, unknown_integrator
from dicetrace.sinks._common import human_bytes
from dicetrace.status import Status
from dicetrace.studies.study_accuracy_grids import grid
from dicetrace.windows import WINDOWS, get_window

#: Presets studied, in the order of the tables and plots.
PRESETS = ("seed", "physical")
PERTURBATIONS = (1e-12, 1e-9, 1e-6)
DEFAULT_WINDOW = "zoom-out"
DEFAULT_N = 300
QUICK_N = 12
DEFAULT_SEED = 0
#: Time cap of the study's runs, s (every reference run settles well before).
T_MAX_S = 20.0
#: First-impact horizon: this long after the reference's first contact, rounded
#: up to a multiple of HORIZON_GRID_S (every step of the study divides it), s.
FIRST_IMPACT_AFTER_S = 0.02
HORIZON_GRID_S = 0.008
#: ICs of the trajectory subsample (first-impact error, energy drift).
N_TRAJ = 24
QUICK_N_TRAJ = 4
#: The own numerical floor of every setting: ICs of a resolved window, moved by a relative FLOOR_REL.
FLOOR_WINDOW = "home"
FLOOR_N = 300
QUICK_FLOOR_N = 12
FLOOR_REL = 1e-12
#: Agreement a setting must reach to count as converged, per preset (the summary's cheapest-setting table).
TARGET_AGREEMENT = {"seed": 0.97, "physical": 0.93}
#: The integrator every other's cheapest converged setting is compared with.
BASELINE_INTEGRATOR = "contact-adaptive"
#: Timed runs: best of this many (quick: 1); one run moved by up to ~1.5x on a loaded machine.
TIMING_REPEAT = 3
#: Memory per IC of the sample, bytes: a reference batch peaked ~1.2 KB per IC (contact-set buffers, summaries),
#: with the ICs, their perturbed copies and the runs the study keeps; rounded up.
BYTES_PER_IC = 2048
#: Seeds the study takes (those of :class:`dicetrace.ics.Sample`).
SEED_RANGE = (0, 2**64)


def check_size(n: int) -> None:
    """Refuse (ValueError naming --n) a sample of ``n`` ICs whose runs will not fit in the available memory."""
    need, avail = int(n) * BYTES_PER_IC, memory.available_memory()
    if avail is not None and need > avail:
        raise ValueError(f"--n {n:,}: the study's runs of {n:,} ICs need about {human_bytes(need)} of memory, "
                         f"{human_bytes(avail)} available: use a smaller --n")


#: Failed statuses (never an outcome), as codes.
FAILED = tuple(int(s) for s in Status if s.failed)


@dataclass(frozen=True)
class Reference:
    """The converged reference: an integrator at a step (and tolerance), checked at half that step."""

    integrator: str = "contact-substep"
    dt_s: float = 1e-4
    tol: float | None = None

    @property
    def check_dt_s(self) -> float:
        return self.dt_s / 2.0

    @property
    def label(self) -> str:
        return f"{self.integrator} dt={self.dt_s:g} s" + ("" if self.tol is None else f" tol={self.tol:g}")

    def config(self, preset: str) -> Config:
        return config_for(preset, self.integrator, self.dt_s, tol=self.tol)


REFERENCE = Reference("contact-substep", 1e-4)
QUICK_REFERENCE = Reference("contact-substep", 2.5e-4)
#: The second, independent reference: error-controlled sub-steps instead of a fixed grid.
SECOND_REFERENCE = Reference("contact-adaptive", 1e-3, 1e-10)
QUICK_SECOND_REFERENCE = Reference("contact-adaptive", 1e-3, 1e-8)

#: CSV columns of the study, in order.
STUDY_COLUMNS = (
    "preset", "integrator", "order", "dt_s", "tol", "tol_growth", "n_ics", "cpu_ms_per_ic", "outcome_agreement",
    "settled_fraction", "settle_time_bias_s", "settle_time_mae_s", "contact_count_bias", "first_impact_error_cm",
    "free_flight_energy_drift", "blow_ups", "time_caps", "own_floor_flips", "own_floor_n", "chaos_floor_1e-12",
    "chaos_floor_1e-09", "chaos_floor_1e-06", "reference_integrator", "reference_dt_s", "reference_self_agreement", "window", "seed",
)


def study_runs(integrator: str, quick: bool = False) -> list[tuple[float, float | None, float | None]]:
    """(dt, tol, tol_growth) of every run of ``integrator`` in the study: its grid's steps × tolerances, uniform
    (growth 0) then loosening over the throw (``study_graded``); fixed steps: tol and growth None."""
    if integrator not in INTEGRATORS:
        raise ValueError(unknown_integrator(integrator))
    s = grid(integrator)
    dts = s.quick_dt_s if quick else s.study_dt_s
    if not INTEGRATORS[integrator].adaptive:
        return [(dt, None, None) for dt in dts]
    tols = s.quick_tol if quick else s.study_tol
    graded = s.quick_graded if quick else s.study_graded
    return [(dt, tol, 0.0) for dt in dts for tol in tols] + [(dt, tol, rate) for dt in dts for rate, tol in graded]


def check_integrators(integrators) -> tuple[str, ...]:
    """The integrators asked for (default: all), each checked against the table."""
    integrators = tuple(integrators or INTEGRATORS)
    for name in integrators:
        if name not in INTEGRATORS:
            raise ValueError(unknown_integrator(name))
    return integrators


def sample_ics(window: str = DEFAULT_WINDOW, n: int = DEFAULT_N, seed: int = DEFAULT_SEED) -> np.ndarray:
    """``n`` seeded uniform ICs (program convention) from a window of the seed slice."""
    box = get_window(window, 2)
    return Sample(SEED_SLICE, box, int(n), "random", int(seed)).block(0, int(n)).ics


def perturb(ics: np.ndarray, rel: float, seed: int) -> np.ndarray:
    """IC + rel·|IC|·ξ with ξ a seeded random unit vector per IC (6-D)."""
    rng = np.random.default_rng([seed, 7919])
    xi = rng.normal(size=ics.shape)
    xi /= np.linalg.norm(xi, axis=1, keepdims=True)
    return ics + rel * np.linalg.norm(ics, axis=1, keepdims=True) * xi


def config_for(preset: str, integrator: str, dt_s: float, t_max_s: float = T_MAX_S, tol: float | None = None,
               tol_growth: float | None = None) -> Config:
    """A run's configuration; an error-controlled integrator without ``tol`` takes the preset's default schedule."""
    return make_config(preset, integrator=integrator, dt_s=dt_s, t_max_s=t_max_s, tol=tol, tol_growth=tol_growth)


@dataclass
class Runs:
    """Summaries of one configuration over the study's ICs (``status``: :class:`~dicetrace.Status` codes)."""

    outcome: np.ndarray
    status: np.ndarray
    t_settle_s: np.ndarray
    n_changes: np.ndarray
    t_first_contact_s: np.ndarray
    cpu_ms_per_ic: float = float("nan")

    @property
    def settled(self) -> np.ndarray:
        return self.status == int(Status.SETTLED)


def run_batch(ics_preset: np.ndarray, cfg: Config, *, threads: int | None = None, timed: bool = False,
              repeat: int = 1) -> Runs:
    """``simulate_batch`` over ICs already in the preset's convention (timed on request: one thread, best of ``repeat``)."""
    from dicetrace.core.loop import BATCH_BLOCK  # lazy: keeps `dicetrace --help` fast (imports numba)
    from dicetrace.simulate import simulate_batch

    cpu = float("nan")
    if timed:
        # warm-up: compile / load the batch kernel (up to BATCH_BLOCK ICs run the single-throw loop instead)
        simulate_batch(ics_preset[: BATCH_BLOCK + 1], config=cfg, threads=1)
        cpu = math.inf
        for _ in range(max(1, int(repeat))):
            t0 = time.process_time()
            r = simulate_batch(ics_preset, config=cfg, threads=1)
            cpu = min(cpu, (time.process_time() - t0) / len(ics_preset) * 1e3)
    else:
        r = simulate_batch(ics_preset, config=cfg, threads=threads)
    m = len(r)
    t_first = np.full(m, np.nan)
    for i in range(m):
        a, b = r.set_offsets[i], r.set_offsets[i + 1]
        if b - a > 1:
            t_first[i] = r.set_steps[a + 1] * cfg.numerics.dt_s
    return Runs(
        outcome=r.outcome.astype(int),
        status=r.status_code.astype(int),
        t_settle_s=r.t_settle_s.astype(float),
        n_changes=(np.diff(r.set_offsets) - 1).astype(int),
        t_first_contact_s=t_first,
        cpu_ms_per_ic=cpu,
    )


def own_floor(ics_preset: np.ndarray, cfg: Config, seed: int, *, rel: float = FLOOR_REL, threads=None) -> int:
    """ICs whose outcome or status changes when moved by a relative ``rel``, both runs by ``cfg``: the setting's own floor."""
    a = run_batch(ics_preset, cfg, threads=threads)
    b = run_batch(perturb(ics_preset, rel, seed), cfg, threads=threads)
    return int(np.sum((a.outcome != b.outcome) | (a.status != b.status)))


def agreement(a: Runs, ref: Runs) -> float:
    """Fraction of ICs with the reference's outcome (unsettled runs disagree): :func:`settled_agreement`."""
    return settled_agreement(a.outcome, a.settled, ref.outcome, ref.settled)


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


def run_trajectory(ic_preset: np.ndarray, cfg: Config, horizon_s: float) -> Trajectory:
    """Trace one IC (preset convention) up to ``horizon_s`` (a multiple of dt) and measure what the study needs."""
    from dicetrace.simulate import Record, simulate  # lazy: keeps `dicetrace --help` fast (imports numba)

    c = replace(cfg, numerics=replace(cfg.numerics, t_max_s=horizon_s))
    r = simulate(ic_preset, config=c, record=Record(states=True, energy=True))
    tr = r.trace
    z = tr.node_pos[:, :, 2]
    touched = np.nonzero((z <= 0.0).any(axis=1))[0]
    last_free = (touched[0] - 1) if len(touched) else len(z) - 1
    e = tr.energy["total"]
    drift = abs(e[last_free] - e[0]) / max(e[0] - cfg.preset.e_rest, 1e-300)
    pos = None
    if r.status is Status.TIME_CAP and r.steps == c.numerics.max_steps:
        pos = tr.node_pos[-1].copy()
    return Trajectory(pos, float(drift))


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
        return pd.DataFrame(self.rows, columns=list(STUDY_COLUMNS))


def _reference(preset, ics, ref_spec: Reference, second: Reference, floor_ics, n_traj: int, seed: int, threads, say):
    """The reference runs of one preset: its summary row, runs, chaos floors and trajectory subsample."""
    say(f"[{preset}] reference {ref_spec.label} on {len(ics)} ICs")
    ref_cfg = ref_spec.config(preset)
    chk_cfg = config_for(preset, ref_spec.integrator, ref_spec.check_dt_s, tol=ref_spec.tol)
    ref = run_batch(ics, ref_cfg, threads=threads)
    chk = run_batch(ics, chk_cfg, threads=threads)
    say(f"[{preset}] second reference {second.label}")
    two = run_batch(ics, second.config(preset), threads=threads)
    # an unsettled run of either reference counts as disagreement (as in `agreement`)
    both = wilson_agreement(np.where(two.settled, two.outcome, -1), np.where(ref.settled, ref.outcome, -2))
    floors = {}
    for rel in PERTURBATIONS:
        say(f"[{preset}] chaos floor {rel:g}")
        floors[rel] = agreement(run_batch(perturb(ics, rel, seed), ref_cfg, threads=threads), ref)
    # trajectory subsample: reference traces at each IC's horizon
    horizons = np.array([first_impact_horizon(t) for t in ref.t_first_contact_s[:n_traj]])
    ref_traj = [run_trajectory(ics[i], ref_cfg, horizons[i]) if np.isfinite(horizons[i]) else None
                for i in range(n_traj)]
    row = {
        "preset": preset,
        "integrator": ref_spec.integrator,
        "dt_s": ref_spec.dt_s,
        "check_dt_s": ref_spec.check_dt_s,
        "self_agreement": agreement(chk, ref),
        "check_first_impact_error_cm": _traj_error(ics, chk_cfg, horizons, ref_traj)[0],
        "second_reference": second.label,
        "references_agreement": both.fraction,
        "references_agreement_lo": both.ci[0],
        "references_agreement_hi": both.ci[1],
        "own_floor_flips": own_floor(floor_ics, ref_cfg, seed, threads=threads),
        "own_floor_n": len(floor_ics),
        "settled_fraction": float(np.mean(ref.settled)),
        "mean_settle_time_s": _mean(ref.t_settle_s[ref.settled]),
        "mean_contact_changes": float(np.mean(ref.n_changes)),
        **{f"chaos_floor_{rel:.0e}": floors[rel] for rel in PERTURBATIONS},
    }
    return row, ref, horizons, ref_traj


def _run_row(preset, integ, dt, tol, growth, ics, ref: Runs, ref_row: dict, horizons, ref_traj, ref_spec, window,
             seed, floor_ics, threads, repeat):
    """One timed run of the study against the reference, and its own floor: its CSV row and CPU cost."""
    cfg = config_for(preset, integ, dt, tol=tol, tol_growth=growth)
    runs = run_batch(ics, cfg, timed=True, repeat=repeat)
    flips = own_floor(floor_ics, cfg, seed, threads=threads)
    both = runs.settled & ref.settled
    t_err = runs.t_settle_s[both] - ref.t_settle_s[both]
    c_err = runs.n_changes[both] - ref.n_changes[both]
    ferr, drift = _traj_error(ics, cfg, horizons, ref_traj)
    return {
        "preset": preset,
        "integrator": integ,
        "order": INTEGRATORS[integ].order,
        "dt_s": dt,
        "tol": float("nan") if tol is None else tol,
        "tol_growth": float("nan") if growth is None else growth,
        "n_ics": len(ics),
        "cpu_ms_per_ic": runs.cpu_ms_per_ic,
        "outcome_agreement": agreement(runs, ref),
        "settled_fraction": float(np.mean(runs.settled)),
        "settle_time_bias_s": float(np.mean(t_err)) if both.any() else float("nan"),
        "settle_time_mae_s": float(np.mean(np.abs(t_err))) if both.any() else float("nan"),
        "contact_count_bias": float(np.mean(c_err)) if both.any() else float("nan"),
        "first_impact_error_cm": ferr,
        "free_flight_energy_drift": drift,
        "blow_ups": int(np.sum(np.isin(runs.status, FAILED))),
        "time_caps": int(np.sum(runs.status == int(Status.TIME_CAP))),
        "own_floor_flips": flips,
        "own_floor_n": len(floor_ics),
        "chaos_floor_1e-12": ref_row["chaos_floor_1e-12"],
        "chaos_floor_1e-09": ref_row["chaos_floor_1e-09"],
        "chaos_floor_1e-06": ref_row["chaos_floor_1e-06"],
        "reference_integrator": ref_spec.integrator,
        "reference_dt_s": ref_spec.dt_s,
        "reference_self_agreement": ref_row["self_agreement"],
        "window": window,
        "seed": seed,
    }


def study(
    *,
    window: str = DEFAULT_WINDOW,
    n: int | None = None,
    seed: int = DEFAULT_SEED,
    quick: bool = False,
    presets=PRESETS,
    integrators=None,
    reference: Reference | None = None,
    n_traj: int | None = None,
    floor_n: int | None = None,
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
        CI size: fewer ICs, each integrator's quick steps, coarser references.
    floor_n
        ICs of the ``home`` window for each setting's own floor (default 300; ``quick``: 12).
    threads
        numba threads for the untimed runs (reference, floors); timed runs use one.
    progress
        Optional callable ``progress(message)``.
    """
    say = progress or (lambda msg: None)
    n = int(n if n is not None else (QUICK_N if quick else DEFAULT_N))
    if n < 2:
        raise ValueError(f"the study needs at least 2 ICs, got n = {n}")
    integrators = check_integrators(integrators)
    for p in presets:
        get_preset(p)
    ref_spec = reference or (QUICK_REFERENCE if quick else REFERENCE)
    second = QUICK_SECOND_REFERENCE if quick else SECOND_REFERENCE
    floor_n = int(floor_n if floor_n is not None else (QUICK_FLOOR_N if quick else FLOOR_N))
    n_traj = min(n, int(n_traj if n_traj is not None else (QUICK_N_TRAJ if quick else N_TRAJ)))
    program = make_config("seed").numerics  # the 2019 program's scheme and step: the cost unit
    ics_prog = sample_ics(window, n, seed)
    floor_prog = sample_ics(FLOOR_WINDOW, floor_n, seed)
    rows, orders, references, ref_runs = [], [], [], {}
    seed_cost = float("nan")
    for preset in presets:
        ics = convert_l(ics_prog, "program", get_preset(preset).l_convention)
        floor_ics = convert_l(floor_prog, "program", get_preset(preset).l_convention)
        ref_row, ref, horizons, ref_traj = _reference(preset, ics, ref_spec, second, floor_ics, n_traj, seed, threads, say)
        references.append(ref_row)
        ref_runs[preset] = ref
        for integ in integrators:
            runs_at = study_runs(integ, quick)
            errs = []
            for dt, tol, growth in runs_at:
                say(f"[{preset}] {integ} dt={dt:g} s" + ("" if tol is None else f" tol={tol:g}")
                    + (f" growing {growth:g}/s" if growth else ""))
                row = _run_row(preset, integ, dt, tol, growth, ics, ref, ref_row, horizons, ref_traj, ref_spec, window,
                               seed, floor_ics, threads, 1 if quick else TIMING_REPEAT)
                rows.append(row)
                if not growth:  # the order is fitted on the uniform tolerances (or the steps)
                    errs.append((tol if tol is not None else dt, row["first_impact_error_cm"]))
                if preset == "seed" and integ == program.integrator and dt == program.dt_s:
                    seed_cost = row["cpu_ms_per_ic"]
            against_tol = any(t is not None for _, t, _ in runs_at)
            orders.append({
                "preset": preset,
                "integrator": integ,
                "declared_order": INTEGRATORS[integ].order,
                # error-controlled runs: the exponent of the error against tol at one dt
                "fitted_order_first_impact": convergence_order([x for x, _ in errs], [e for _, e in errs])
                if len(errs) >= 2 else float("nan"),
                "against": "tol" if against_tol else "dt",
            })
    notes = [] if window in WINDOWS else [f"window given as coordinates: {window}"]
    comparison = compare_presets(ref_runs["seed"], ref_runs["physical"]) if {"seed", "physical"} <= set(ref_runs) else {}
    return StudyResult(rows, orders, references, window, n, seed, quick, seed_cost, notes, comparison)


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
