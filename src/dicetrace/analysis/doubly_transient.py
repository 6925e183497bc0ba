"""Doubly transient chaos: local slopes of f(ε) and their crossover, settling hazards, exponents on survivors.

In a dissipative system whose chaotic saddle itself decays (the energy falls, so the die
can climb over fewer and fewer edges), the transient is *doubly* transient (Motter, Gruiz,
Károlyi & Tél 2013, PRL 111:194101; Chen, Nishikawa & Motter 2017, PRX 7:021040): the
hazard of leaving rises with time instead of settling to a constant escape rate κ, and the
basin borders look fractal only down to a crossover scale ε_c, below which they are smooth
(uncertainty exponent α → 1).  The measures here:

* :func:`local_slopes`: the fraction ``f(ε)`` of IC pairs ``ε`` apart whose outcomes differ
  and its local slope ``d ln f / d ln ε`` between neighbouring scales, with bootstrap errors
  (the pairs resampled by base point, so that the scales' correlation is kept);
* :func:`crossover_fit`: ``ε_c`` from ``g = A ε / (1 + (ε/ε_c)^(1-β))``, ``f = f_sat g / (1 + g)``:
  slope 1 below ε_c, β above it (the local slope of ``g`` halfway at ε_c), saturating at ``f_sat``;
  bootstrap errors;
* :func:`hazard_curve`, :func:`hazard_windows`: the hazard ``h(t)`` of lifetimes (piecewise
  constant maximum likelihood, censoring allowed), in bins and between quantiles;
* :func:`discrete_hazard`: the hazard per bounce, ``P(N = n | N ≥ n)``;
* :func:`covariate_hazard`: the hazard per unit time as a function of a covariate (energy);
* :func:`commit_steps`: when a throw commits to its final face (its last contact with a node
  off the face it lands on) and how many landings came before, from its contact sets;
* :func:`pair_divergence`: a throw and its neighbour, their distance and the throw's energy;
* :func:`compare`: two measured values with errors, their z-score and a verdict;
* :func:`hazard_shape`: whether a hazard across its quantile windows rises steadily, dips before it rises, or is
  not monotone (each step's z-score);
* :func:`tail_scan`: the late hazard past a quantile of the lifetimes, over nested tails, with the choice of
  the tail's start as its systematic (:func:`dicetrace.analysis.robustness.range_scan`).
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from dicetrace import body

from dicetrace.simulate import Record, simulate, simulate_batch

__all__ = ["LocalSlopes", "local_slopes", "Crossover", "crossover_fit", "Hazard", "hazard_curve", "hazard_windows",
           "discrete_hazard", "covariate_hazard", "FACE_NODE_MASK", "commit_steps", "perturbed", "floor_test", "throw_floor",
           "pair_divergence", "compare", "pair_outcomes", "pair_verdicts", "hazard_summary", "hazard_shape",
           "tail_scan", "tail_scan_windows"]

#: Bit mask of the four nodes of each face (face 1..6; bit k-1 is node k; docs/model.md §3).
FACE_NODE_MASK = body.FACE_NODE_MASK  # (re-exported: the bitmask of each face's nodes)


def _boot_weights(n: int, n_boot: int, rng) -> np.ndarray:
    """Multinomial resampling weights (n_boot, n): row b says how often each base point is drawn."""
    return np.random.default_rng(rng).multinomial(n, np.full(n, 1.0 / n), size=int(n_boot))


@dataclasses.dataclass(frozen=True)
class LocalSlopes:
    """``f(ε)`` (with its binomial stderr and the changed counts) and the local slopes between neighbouring scales
    at their geometric means ``eps_mid``, with bootstrap standard errors (nan where a scale has no change)."""

    eps: np.ndarray
    f: np.ndarray
    f_stderr: np.ndarray
    changed: np.ndarray
    n: np.ndarray
    eps_mid: np.ndarray
    slope: np.ndarray
    slope_stderr: np.ndarray


def _slopes(counts: np.ndarray, n: np.ndarray, leps: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        lf = np.where(counts > 0, np.log(counts / n), np.nan)
    return np.diff(lf, axis=-1) / np.diff(leps)


def local_slopes(changed, eps, *, valid=None, n_boot: int = 400, rng=0) -> LocalSlopes:
    """Local slopes of ``f(ε)`` from a (n_pairs, n_scales) boolean array: pair i at scale s changed outcome.

    ``valid`` (same shape, default all): pairs that count (a throw that did not settle is left out).
    The bootstrap resamples the base points (rows) ``n_boot`` times.
    """
    c = np.asarray(changed, dtype=bool)
    eps = np.asarray(eps, dtype=float).ravel()
    if c.ndim != 2 or c.shape[1] != len(eps) or len(eps) < 2:
        raise ValueError(f"changed must be (n_pairs, {len(eps)}) with at least 2 scales, got shape {c.shape}")
    if np.any(np.diff(eps) <= 0) or not np.all(eps > 0):
        raise ValueError("eps must be positive and increasing")
    v = np.ones_like(c) if valid is None else np.asarray(valid, dtype=bool)
    cv = (c & v).astype(np.float64)
    counts, n = cv.sum(axis=0), v.sum(axis=0).astype(np.float64)
    f = np.divide(counts, n, out=np.full(len(eps), np.nan), where=n > 0)
    f_se = np.sqrt(f * (1 - f) / np.maximum(n, 1))
    leps = np.log(eps)
    slope = _slopes(counts, n, leps)
    w = _boot_weights(len(c), n_boot, rng).astype(np.float64)
    sb = _slopes(w @ cv, w @ v.astype(np.float64), leps)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a column of resamples without any change
        ok = np.isfinite(sb).mean(axis=0) >= 0.9  # a slope whose resamples often have no change: no error bar
        se = np.where(ok & np.isfinite(slope), np.nanstd(np.where(np.isfinite(sb), sb, np.nan), axis=0, ddof=1),
                      np.nan)
    return LocalSlopes(eps, f, f_se, counts.astype(np.int64), n.astype(np.int64), np.exp(leps[:-1] + np.diff(leps) / 2),
                       slope, se)


@dataclasses.dataclass(frozen=True)
class Crossover:
    """The crossover of ``g = A ε / (1 + (ε/ε_c)^(1-β))``, ``f = f_sat g / (1 + g)``: ``eps_c`` with the bootstrap standard error of
    ``log10 eps_c``, the exponent ``beta`` above it (stderr), the scales used and a ``status``:
    ``fitted`` (ε_c inside the scales used), ``below`` (ε_c below them: no smooth range resolved, slope β
    throughout), ``above`` (above them: slope 1 throughout) or ``too few scales``."""

    eps_c: float
    log10_eps_c_stderr: float
    beta: float
    beta_stderr: float
    amplitude: float
    used: np.ndarray
    status: str
    n_boot: int


#: A fitted small-scale slope β this close to 1 is no crossover (the model's ε_c is then not identified).
BETA_FLAT = 1e-6


def _fit_crossover(leps: np.ndarray, lf: np.ndarray, w: np.ndarray, lo: float, hi: float, f_sat: float | None):
    from scipy.optimize import least_squares  # scipy.optimize is slow to import: only for this fit

    def model(p):
        lg = p[0] + leps - np.log1p(np.exp((1.0 - p[2]) * (leps - p[1])))
        return lg if f_sat is None else math.log(f_sat) + lg - np.logaddexp(0.0, lg)

    best = None
    for l0 in np.linspace(lo, hi, 5):  # a few starts: the crossover's position is the hard parameter
        p0 = np.array([lf[0] - leps[0], l0, 0.5])
        try:
            r = least_squares(lambda p: w * (model(p) - lf), p0, bounds=([-np.inf, lo, 0.0], [np.inf, hi, 1.0]))
        except ValueError:
            continue
        if best is None or r.cost < best.cost:
            best = r
    return best.x if best is not None else None


def crossover_fit(changed, eps, *, used, valid=None, f_sat: float | None = None, n_boot: int = 200,
                  rng=0) -> Crossover:
    """Fit the crossover model to ``f(ε)`` on the scales ``used`` (a boolean mask), weighted by the binomial
    variance of ``ln f``; ε_c is bounded to two decades either side of the scales used, β to [0, 1].
    ``f_sat``: the fraction of unrelated outcomes, ``1 - Σ p²`` (None: no saturation, ``f = g``).  The
    bootstrap refits the model to ``n_boot`` resamples of the base points."""
    c = np.asarray(changed, dtype=bool)
    eps = np.asarray(eps, dtype=float).ravel()
    used = np.asarray(used, dtype=bool).ravel() & (eps > 0)
    v = np.ones_like(c) if valid is None else np.asarray(valid, dtype=bool)
    cv, vv = (c & v).astype(np.float64), v.astype(np.float64)
    counts, n = cv.sum(axis=0), vv.sum(axis=0)
    used = used & (counts > 0)
    if used.sum() < 4:
        return Crossover(math.nan, math.nan, math.nan, math.nan, math.nan, used, "too few scales", 0)
    leps = np.log(eps[used])
    lo, hi = leps[0] - 2 * math.log(10), leps[-1] + 2 * math.log(10)

    def fit(cu, nu):
        f = cu / nu
        if np.any(cu <= 0):
            return None
        w = np.sqrt(nu * f / np.maximum(1 - f, 1e-12))
        return _fit_crossover(leps, np.log(f), w, lo, hi, f_sat)

    p = fit(counts[used], n[used])
    if p is None:
        return Crossover(math.nan, math.nan, math.nan, math.nan, math.nan, used, "too few scales", 0)
    wb = _boot_weights(len(c), n_boot, rng).astype(np.float64)
    cb, nb = wb @ cv[:, used], wb @ vv[:, used]
    boots = [q for q in (fit(cb[b], nb[b]) for b in range(len(wb))) if q is not None]
    bs = np.array(boots) if boots else np.full((1, 3), np.nan)
    lc = p[1]
    status = "fitted" if leps[0] <= lc <= leps[-1] else ("below" if lc < leps[0] else "above")
    if p[2] >= 1.0 - BETA_FLAT:
        # slope 1 on both sides of ε_c: no crossover on the scales, whose position the fit cannot then tell
        # (the model no longer depends on it); smooth on every scale used, so it lies above them
        status = "above"
    return Crossover(float(math.exp(lc)), float(np.std(bs[:, 1], ddof=1) / math.log(10)) if len(boots) > 1 else math.nan,
                     float(p[2]), float(np.std(bs[:, 2], ddof=1)) if len(boots) > 1 else math.nan, float(math.exp(p[0])),
                     used, status, len(boots))


@dataclasses.dataclass(frozen=True)
class Hazard:
    """A piecewise-constant hazard: bins ``[t0, t1)``, rate ``h`` (1/unit) with stderr ``h/√events``, the events and
    the exposure (total time at risk in the bin) and the number at risk at each bin's start."""

    t0: np.ndarray
    t1: np.ndarray
    h: np.ndarray
    stderr: np.ndarray
    events: np.ndarray
    exposure: np.ndarray
    at_risk: np.ndarray

    def as_dict(self) -> dict:
        """The curve for a results file (JSON): bins, rates, their errors, events and numbers at risk."""
        return {"t0": self.t0.tolist(), "t1": self.t1.tolist(), "h": self.h.tolist(), "stderr": self.stderr.tolist(),
                "events": self.events.tolist(), "at_risk": self.at_risk.tolist()}


def _lifetimes(lifetimes, censored):
    t = np.asarray(lifetimes, dtype=float).ravel()
    if len(t) == 0 or not np.all(np.isfinite(t)):
        raise ValueError("lifetimes must be a non-empty array of finite numbers")
    cen = np.zeros(len(t), dtype=bool) if censored is None else np.asarray(censored, dtype=bool).ravel()
    if cen.shape != t.shape:
        raise ValueError("censored must have one flag per lifetime")
    return t, cen


def hazard_curve(lifetimes, edges, *, censored=None) -> Hazard:
    """Maximum-likelihood piecewise-constant hazard of ``lifetimes`` on the bins between ``edges``: per bin, the
    events in it over the time the lifetimes spend in it (``censored`` lifetimes add time, never an event)."""
    t, cen = _lifetimes(lifetimes, censored)
    e = np.asarray(edges, dtype=float).ravel()
    if len(e) < 2 or np.any(np.diff(e) <= 0):
        raise ValueError("edges must be increasing, at least two")
    a, b = e[:-1], e[1:]
    expo = np.clip(np.minimum(t[:, None], b[None]) - a[None], 0, None).sum(axis=0)
    ev = ((t[:, None] >= a[None]) & (t[:, None] < b[None]) & ~cen[:, None]).sum(axis=0)
    risk = (t[:, None] >= a[None]).sum(axis=0)
    h = np.divide(ev, expo, out=np.full(len(a), np.nan), where=expo > 0)
    se = np.divide(h, np.sqrt(ev), out=np.full(len(a), np.nan), where=ev > 0)
    return Hazard(a, b, h, se, ev.astype(np.int64), expo, risk.astype(np.int64))


def hazard_windows(lifetimes, quantiles=(0.5, 0.75, 0.9, 0.97), *, censored=None, min_events: int = 20) -> Hazard:
    """The hazard between successive ``quantiles`` of the lifetimes (the last window ends at the largest lifetime):
    a rate that rises from window to window is no steady escape rate.  Windows with fewer than ``min_events``
    events are dropped."""
    t, cen = _lifetimes(lifetimes, censored)
    q = np.quantile(t, np.asarray(quantiles, dtype=float))
    edges = np.unique(np.append(q, np.nextafter(t.max(), np.inf)))
    hz = hazard_curve(t, edges, censored=cen)
    keep = hz.events >= min_events
    return Hazard(*(getattr(hz, f.name)[keep] for f in dataclasses.fields(Hazard)))


def discrete_hazard(counts, *, min_at_risk: int = 20) -> dict:
    """Hazard per step of a discrete lifetime (the bounce at which a throw commits): ``h_n = P(N = n | N ≥ n)`` with
    its binomial stderr, for n = 0, 1, ... while at least ``min_at_risk`` lifetimes reach n."""
    nn = np.asarray(counts, dtype=np.int64).ravel()
    if nn.size == 0 or np.any(nn < 0):
        raise ValueError("counts must be a non-empty array of integers >= 0")
    out = {"n": [], "h": [], "stderr": [], "at_risk": [], "events": []}
    for k in range(int(nn.max()) + 1):
        risk = int((nn >= k).sum())
        if risk < min_at_risk:
            break
        ev = int((nn == k).sum())
        h = ev / risk
        out["n"].append(k)
        out["h"].append(h)
        out["stderr"].append(math.sqrt(h * (1 - h) / risk))
        out["at_risk"].append(risk)
        out["events"].append(ev)
    return {k: np.asarray(v) for k, v in out.items()}


def covariate_hazard(times, values, event_times, edges, *, events=None) -> Hazard:
    """Hazard per unit time as a function of a covariate ``x(t)`` (the energy): per bin of ``x`` (``edges``), the
    events that happen while ``x`` is in the bin over the time spent there before the event.

    ``times[i]``, ``values[i]``: the sampled time series of throw i (the value held over each sample interval);
    ``event_times[i]``: when it ends (``events[i]`` False: censored, it adds time and no event).  The returned
    ``t0``/``t1`` are the covariate bins."""
    e = np.asarray(edges, dtype=float).ravel()
    if len(e) < 2 or np.any(np.diff(e) <= 0):
        raise ValueError("edges must be increasing, at least two")
    nb = len(e) - 1
    expo, ev = np.zeros(nb), np.zeros(nb, dtype=np.int64)
    risk = np.zeros(nb, dtype=np.int64)
    for i, (t, x, te) in enumerate(zip(times, values, event_times)):
        t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
        stop = np.searchsorted(t, te, side="right")  # samples at or before the event
        if stop == 0:
            continue
        dt = np.diff(np.append(t[:stop], te))
        k = np.searchsorted(e, x[:stop], side="right") - 1
        inb = (k >= 0) & (k < nb)
        np.add.at(expo, k[inb], dt[inb])
        np.add.at(risk, np.unique(k[inb]), 1)
        if (events is None or events[i]) and inb[stop - 1]:
            ev[k[stop - 1]] += 1
    h = np.divide(ev, expo, out=np.full(nb, np.nan), where=expo > 0)
    se = np.divide(h, np.sqrt(ev), out=np.full(nb, np.nan), where=ev > 0)
    return Hazard(e[:-1], e[1:], h, se, ev, expo, risk)


def commit_steps(sets, set_steps, set_offsets, outcome, end_steps) -> tuple[np.ndarray, np.ndarray]:
    """When each throw commits to its final face, and the landings before that, from its contact sets.

    The face it rests on is the one opposite ``outcome`` (the face up).  The throw commits at the first
    contact change after its last contact set holding a node off that face (from then on only the final
    face's nodes touch); a throw that never touches another face commits at its first contact.  A landing is a
    change from no contact to contact; ``landings`` counts those at or before the commit.  Throws without an
    outcome (``outcome`` < 1) get step -1 and landings -1.  ``end_steps``: each throw's last step (a throw whose
    last set is off its face commits then).
    """
    sets = np.asarray(sets, dtype=np.int64)
    steps = np.asarray(set_steps, dtype=np.int64)
    off = np.asarray(set_offsets, dtype=np.int64)
    out = np.asarray(outcome, dtype=np.int64)
    m = len(out)
    commit, landings = np.full(m, -1, dtype=np.int64), np.full(m, -1, dtype=np.int64)
    for i in range(m):
        if not 1 <= out[i] <= 6:
            continue
        s, st = sets[off[i]:off[i + 1]], steps[off[i]:off[i + 1]]
        foreign = np.flatnonzero(s & ~FACE_NODE_MASK[7 - int(out[i])] & 0xFF)
        if len(foreign):
            j = int(foreign[-1]) + 1
        else:
            touch = np.flatnonzero(s != 0)
            j = int(touch[0]) if len(touch) else len(s)
        commit[i] = st[j] if j < len(s) else int(end_steps[i])
        land = np.flatnonzero((s[:-1] == 0) & (s[1:] != 0)) + 1
        landings[i] = int((land <= min(j, len(s) - 1)).sum())
    return commit, landings


def perturbed(ics, eps: float, rng) -> np.ndarray:
    """The ICs moved by ``eps · |ic| · ξ``, ξ a random unit vector of the 6-D IC space per row."""
    ics = np.asarray(ics, dtype=float)
    u = np.random.default_rng(rng).standard_normal(ics.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return ics + float(eps) * np.linalg.norm(ics, axis=1, keepdims=True) * u


def floor_test(changed, changed_tight, *, valid=None, confidence: float = 0.95) -> dict:
    """The numerical floor of a pair measurement: per scale, the fraction of pairs whose verdict (changed or not)
    differs between the run and the same pairs at a tighter tolerance, with its Wilson interval."""
    from scipy import stats  # scipy.stats is slow to import: only for these tests

    a, b = np.asarray(changed, dtype=bool), np.asarray(changed_tight, dtype=bool)
    v = np.ones_like(a) if valid is None else np.asarray(valid, dtype=bool)
    k, n = ((a != b) & v).sum(axis=0).astype(float), v.sum(axis=0).astype(float)
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        c = (p + z * z / (2 * n)) / (1 + z * z / n)
        hw = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return {"fraction": p, "lo": np.clip(c - hw, 0, 1), "hi": np.clip(c + hw, 0, 1), "flips": k.astype(np.int64),
            "n": n.astype(np.int64)}


def throw_floor(outcome, outcome_tight, *, confidence: float = 0.95) -> dict:
    """The numerical floor per throw: the fraction of throws whose outcome changes at the tighter tolerance, with its
    Wilson interval.  A pair's verdict can change only where one of its two throws does, so twice this fraction
    bounds the pair floor at every scale."""
    a, b = np.asarray(outcome).ravel(), np.asarray(outcome_tight).ravel()
    fl = floor_test((a != b)[:, None], np.zeros((a.size, 1), dtype=bool), confidence=confidence)
    return {k: v[0] for k, v in fl.items()}


def _state_distance(a, b, n: int, cfg, tau: float) -> np.ndarray:
    half, inertia = cfg.preset.half_side_cm, cfg.preset.inertia

    def state(tr):
        return np.concatenate([tr.node_pos[:n].reshape(n, 24), tau * tr.cm_vel[:n], tau * half * tr.L[:n] / inertia],
                              axis=1)

    return np.linalg.norm(state(a.trace) - state(b.trace), axis=1)


def pair_divergence(ic, config, *, delta: float = 1e-10, rng=0, time_scale_s: float = 0.01):
    """A throw (``ic`` in the preset's L convention) and its neighbour at ``delta · |ic|`` (a random 6-D direction):
    times (s), their state distance (cm; the metric of :func:`dicetrace.analysis.transient.throw_divergence`), the
    throw's energy above rest in units of the energy that stands the die on an edge, its first-contact time (s) and
    the throw itself (a ``Roll``)."""

    cfg = config
    ic = np.asarray(ic, dtype=float)
    ic2 = perturbed(ic[None], delta, rng)[0]
    a = simulate(ic, config=cfg, record=Record(states=True, energy=True))
    b = simulate(ic2, config=cfg, record=Record(states=True, energy=False))
    n = min(len(a.trace.t_s), len(b.trace.t_s))
    d = _state_distance(a, b, n, cfg, time_scale_s)
    p = cfg.preset
    e_edge = p.e_rest * (math.sqrt(2.0) - 1.0)
    energy = (a.trace.energy["total"] - p.e_rest) / e_edge
    t_contact = a.contact_steps[1] * a.dt_s if len(a.contact_steps) > 1 else math.nan
    return a.trace.t_s[:n].copy(), d, energy, float(t_contact), a


def compare(x: float, x_err: float, y: float, y_err: float) -> dict:
    """Two measured values: their difference, its error (in quadrature), the z-score and a verdict: ``consistent``
    (|z| < 2), ``inconsistent`` (|z| > 3), else ``undetermined``; ``undetermined`` where a value or error is missing."""
    vals = (x, x_err, y, y_err)
    if not all(v is not None and math.isfinite(v) for v in vals):
        return {"x": x, "x_err": x_err, "y": y, "y_err": y_err, "diff": math.nan, "diff_err": math.nan, "z": math.nan,
                "verdict": "undetermined"}
    diff, err = x - y, math.hypot(x_err, y_err)
    z = diff / err if err > 0 else (0.0 if diff == 0 else math.inf)
    verdict = "consistent" if abs(z) < 2 else ("inconsistent" if abs(z) > 3 else "undetermined")
    return {"x": x, "x_err": x_err, "y": y, "y_err": y_err, "diff": diff, "diff_err": err, "z": z, "verdict": verdict}


def pair_outcomes(ics, moved, config):
    """The throws of ``ics`` and of each perturbed copy in ``moved`` (:func:`perturbed`), in one batch at
    ``config``: (the batch, its outcomes as a (len(moved) + 1, len(ics)) int64 array, row 0 the unperturbed)."""
    b = simulate_batch(np.concatenate([ics, *moved]), config=config)
    return b, b.outcome.reshape(len(moved) + 1, len(ics)).astype(np.int64)


def pair_verdicts(out):
    """From :func:`pair_outcomes`' outcomes: (changed, valid), (n, scales) each: the perturbed throw's face differs
    from the unperturbed one's, and both settled on a face."""
    return (out[1:] != out[0]).T, ((out[1:] >= 1) & (out[0] >= 1)).T


def hazard_summary(t_settle, t_commit, landings, t_cap) -> dict:
    """The hazards of settling and of committing to the final face against time (throws past ``t_cap`` censored):
    each one's curve, its windows, κ over the middle of the lifetimes, the late κ and whether it rises from the
    first window (:func:`compare`); and the hazard per landing (:func:`discrete_hazard`)."""
    res = {}
    for key, t in (("settle", t_settle), ("commit", t_commit)):
        cen = t >= t_cap
        edges = np.linspace(0.0, float(np.quantile(t, 0.995)), 25)
        hc, hw = hazard_curve(t, edges, censored=cen), hazard_windows(t, censored=cen)
        mid = hazard_curve(t, np.quantile(t, [0.5, 0.9]), censored=cen)
        rising = compare(float(hw.h[-1]), float(hw.stderr[-1]), float(hw.h[0]), float(hw.stderr[0])) if len(hw.h) > 1 \
            else compare(math.nan, math.nan, math.nan, math.nan)
        res[key] = {"median_s": float(np.median(t)), "curve": hc.as_dict(), "windows": hw.as_dict(),
                    "kappa_mid": float(mid.h[0]), "kappa_mid_stderr": float(mid.stderr[0]),
                    "kappa_mid_range_s": [float(mid.t0[0]), float(mid.t1[0])],
                    "kappa_late": float(hw.h[-1]) if len(hw.h) else math.nan,
                    "kappa_late_stderr": float(hw.stderr[-1]) if len(hw.h) else math.nan,
                    "kappa_late_from_s": float(hw.t0[-1]) if len(hw.h) else math.nan,
                    "late_minus_first": rising}
    bh = discrete_hazard(landings)
    res["bounce"] = {k: v.tolist() for k, v in bh.items()}
    return res


#: A step between neighbouring windows is a fall where its z-score is below −DIP_Z (a dip), and counts against a
#: monotone rise where it is below −FALL_Z; the hazard rises where the last window exceeds the first by RISE_Z.
DIP_Z, FALL_Z, RISE_Z = 3.0, 2.0, 3.0


def hazard_shape(h, stderr) -> dict:
    """The shape of a hazard across successive windows (``h`` ± ``stderr``, earliest first): each step's difference,
    error and z-score, and ``shape``: ``"rises"`` (the last above the first by more than RISE_Z errors and no step
    falling by more than FALL_Z), ``"dips, then rises"`` (a step falls by more than DIP_Z errors to a lowest window
    after the first, and the last lies above the lowest by more than RISE_Z), ``"not monotone"`` (a step falls by
    more than FALL_Z otherwise), ``"rises weakly"`` (no step falls by more than FALL_Z, the last lies above the first by
    FALL_Z to RISE_Z errors),
    ``"flat"`` (no step, and the ends, differ by FALL_Z errors) or ``"undetermined"`` (anything else, or fewer
    than two windows)."""
    h, se = np.asarray(h, float), np.asarray(stderr, float)
    steps = []
    for a, b, ea, eb in zip(h[:-1], h[1:], se[:-1], se[1:]):
        c = compare(float(b), float(eb), float(a), float(ea))
        steps.append({"diff": c["diff"], "diff_err": c["diff_err"], "z": c["z"]})
    out = {"steps": steps, "min_step_z": min((s["z"] for s in steps), default=math.nan)}
    if len(h) < 2 or not np.all(np.isfinite(h)) or not np.all(np.isfinite(se)):
        out.update(shape="undetermined", rise_z=math.nan)
        return out
    rise = compare(float(h[-1]), float(se[-1]), float(h[0]), float(se[0]))["z"]
    low = int(np.argmin(h))
    after_low = compare(float(h[-1]), float(se[-1]), float(h[low]), float(se[low]))["z"]
    zs = np.array([s["z"] for s in steps])
    if zs.min() < -DIP_Z and low > 0 and after_low > RISE_Z:
        shape = "dips, then rises"
    elif zs.min() < -FALL_Z:
        shape = "not monotone"
    elif rise > RISE_Z:
        shape = "rises"
    elif rise > FALL_Z:
        shape = "rises weakly"
    elif abs(rise) < FALL_Z and np.all(np.abs(zs) < FALL_Z):
        shape = "flat"
    else:
        shape = "undetermined"
    out.update(shape=shape, rise_z=rise, lowest_window=low, rise_from_lowest_z=after_low)
    return out


def tail_scan(lifetimes, *, censored=None, starts=(0.99, 0.97, 0.95, 0.9), reference: float = 0.97,
              min_events: int = 20) -> dict:
    """The hazard past the quantile ``q`` of the lifetimes for each of ``starts`` (later starts first: nested tails,
    the shortest first), through :func:`~dicetrace.analysis.robustness.range_scan`: the value at ``reference``
    with its Poisson error, and how far the other tails move it (one-sided).  A tail with fewer than
    ``min_events`` events gives no value; where the reference tail has none, the value, its errors and the
    systematic are None (``values`` still lists the other tails)."""
    from .robustness import range_scan

    t, cen = _lifetimes(lifetimes, censored)
    top = float(np.nextafter(t.max(), np.inf))
    qs = [float(q) for q in starts]

    def fit(lo, hi):
        t0 = float(np.quantile(t, lo))
        hz = hazard_curve(t, [t0, top], censored=cen)
        if hz.events[0] < min_events:
            return math.nan
        return float(hz.h[0]), float(hz.stderr[0])

    ranges = [(q, 1.0) for q in qs]
    try:
        out = range_scan(fit, ranges, widths=[1.0 - q for q in qs], reference=qs.index(reference)).as_dict()
    except ValueError:  # too few events past the reference quantile: no value, the other tails still listed
        vals = [fit(*r) for r in ranges]
        out = {"ranges": [list(r) for r in ranges], "widths": [1.0 - q for q in qs],
               "values": [v[0] if isinstance(v, tuple) else None for v in vals],
               "stderrs": [v[1] if isinstance(v, tuple) else None for v in vals], "reference": qs.index(reference),
               **{k: None for k in ("value", "stat", "syst_lo", "syst_hi", "syst", "syst_dominates", "n_syst",
                                    "extrapolated", "extrapolated_stderr", "trend")}}
    out.update(starts=qs, reference_start=float(reference),
               from_s=[float(np.quantile(t, q)) for q in qs])
    return out


def tail_scan_windows(windows, *, quantiles=(0.5, 0.75, 0.9, 0.97)) -> dict:
    """:func:`tail_scan` from a hazard's quantile windows alone (``windows``: :meth:`Hazard.as_dict` of
    :func:`hazard_windows`, whose bins start at ``quantiles``): the hazard past each window's start is the events of
    that window and the later ones over their exposure (each window's events over its rate), its error that over
    √events; the last window (past the last quantile) is quoted, the earlier starts give the one-sided
    systematic.  Every field is None where the windows do not match ``quantiles`` (a window was dropped)."""
    from .robustness import range_scan

    h, ev = np.asarray(windows["h"], float), np.asarray(windows["events"], float)
    qs = [float(q) for q in quantiles]
    if len(h) != len(qs) or not np.all(np.isfinite(h)) or np.any(h <= 0):
        return {k: None for k in ("value", "stat", "syst_lo", "syst_hi", "syst", "syst_dominates", "values",
                                  "stderrs", "ranges", "starts")}
    expo = ev / h
    start_of = {q: i for i, q in enumerate(qs)}

    def fit(lo, hi):
        i = start_of[lo]
        e, x = ev[i:].sum(), expo[i:].sum()
        return float(e / x), float(e / x / math.sqrt(e))

    out = range_scan(fit, [(q, 1.0) for q in qs[::-1]], widths=[1.0 - q for q in qs[::-1]]).as_dict()
    out["starts"] = qs[::-1]
    return out
