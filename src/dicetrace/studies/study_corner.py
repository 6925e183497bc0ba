"""Study m (corner): the corner balance: its two unstable rates, the faces around it, triple points of converged maps (4.3).

The writeup (section 4.3) argued that "a vertex in 6-D must connect 7
cells, so IC⁶ has none".  A die balanced on one corner is an equilibrium
with two unstable directions, so the throws that end on it form a set of
codimension 2; a generic 2-D slice then meets it at isolated points where
three faces meet.  Here:

1. **Rates** (:mod:`dicetrace.analysis.corner`): the analytic rates of each
   preset (rigid pivot; ``physical``: the slipping pivot's cubic) against
   the simulator's: the die released at rest 10⁻⁸ rad off the balance in
   several directions, the tilt's growth fitted over the linear range, at a
   uniform tight tolerance (``physical``: ``contact-tsit5`` at 10⁻¹⁰, no
   growth; the ``seed`` force law with ``contact-adaptive`` at 10⁻⁹, released
   turning because its friction law has no direction at rest).  ``physical``'s
   error budget: the spread over directions, the shift when the output step
   (which caps the sub-steps) and the tolerance change together, and the fit
   range's one-sided systematic (:func:`~dicetrace.analysis.robustness.range_scan`
   over the fit's end and start).  The program's own integrator (``seed``,
   semi-implicit Euler) is run too.
2. **The face map around the balance**: releases on rings of tilt 10⁻⁸ …
   10⁻² rad and every direction, which face comes up; the borders between
   the sectors bisected in direction to 10⁻⁹ rad.
3. **Triple points of converged maps**: converged outcome maps of the seed
   slice (``seed`` force law, ``contact-adaptive`` at a uniform 10⁻⁹, 100×
   tighter than the converged model of studies j–l, with its convergence
   certificate against 10⁻¹⁰), the boxes where exactly three faces meet
   cleanly, each refined with ``find_vertices`` with the same model down to
   10⁻¹¹ (slice units), three sectors checked on circles of radius 10⁻³ … 10⁻⁷ of
   the window, and how close each point's throw comes to a corner balance
   (:func:`~dicetrace.analysis.corner_slice.corner_distance`) against random
   throws and throws on two-face borders.  Each located point is examined
   again by two independent integrators (:func:`reproduce`): the faces on
   circles of 10⁻⁷ … 10⁻¹⁰ of the window, and the point located again, whose
   spread against the hunt's bisection box says to what scale the location is
   the model's and not one integrator's.

The figures and tables are drawn by :mod:`dicetrace.studies.study_corner_render`.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from dicetrace.analysis.corner import (
    EDGE_AZIMUTHS,
    FACE_AZIMUTHS,
    corner_balance,
    corner_release,
    corner_release_rate,
    corner_tilt,
    face_map,
    sector_boundaries,
)
from dicetrace.analysis.corner_slice import arcs, circle_sectors, clean_junctions, corner_distance, refine_triple
from dicetrace.analysis.robustness import common_scale, one_sided_z, range_scan, relocate
from dicetrace.analysis.simulator import classify_on_slice
from dicetrace.analysis.transient import certify_map, converged_verdict
from dicetrace.ics import seed_slice
from dicetrace.simulate import Record, simulate
from dicetrace.studies.context import Computed, Context, Options, Output, window_ranges, write_json
from dicetrace.studies.study_corner_models import (HUNT_MODEL, MAP_MODEL, MODEL_OPTS, PHYSICAL,  # noqa: F401
                                                   SEED_CONVERGED, SEED_DISCRETE, STUDY_CONVERGED, config)
from dicetrace.studies.study_corner_render import render, verdict  # noqa: F401  (the study's render)

NAME = "corner"
WINDOWS = ("home", "zoom-out")
#: Ring tilts (rad) of the face maps, per model; (tilt, spin ratio) rings.
RINGS = {"physical": ((1e-8, 0.0), (1e-6, 0.0), (1e-4, 0.0), (1e-2, 0.0), (1e-6, 1.0)),
         "seed-converged": ((1e-3, 0.0), (1e-2, 0.0), (1e-4, 1.0), (1e-3, 1.0)),
         "seed-discrete": ((1e-8, 0.0), (1e-6, 0.0), (1e-4, 0.0), (1e-2, 0.0))}
#: Circle radii about a located point, as fractions of the window's width.
RADII = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
#: The located points re-examined with independent integrators (10× tighter than the hunt's): circles of these
#: radii (fractions of the window's width), and the point located again from a box of RELOCATE_HALF about it.
INDEPENDENT = {"contact-dop853": {"preset": "seed", "integrator": "contact-dop853", "tol": 1e-10},
               "contact-tsit5": {"preset": "seed", "integrator": "contact-tsit5", "tol": 1e-10}}
REPRO_RADII = (1e-7, 1e-8, 1e-9, 1e-10)
RELOCATE_HALF = 1e-7
#: The corner rate's error budget (physical): step caps (s) and tolerances of the numerics, and the fit ranges
#: (rad): the end of the fit from 1e-4 to 3e-3 rad at the start 1e4 × tilt0, and the start a decade later.
STEP_CAPS = ((5e-4, 1e-10), (2e-4, 1e-10), (1e-4, 1e-10), (1e-4, 1e-11))
FIT_ENDS = (1e-4, 3e-4, 1e-3, 3e-3)


def _model_text(opts: dict) -> str:
    cfg = config(opts)
    n = cfg.numerics
    tol = f" tol {n.tol:g}" + (f" growing {n.tol_growth:g}/s" if n.tol_growth else " uniform") \
        if n.spec.adaptive else f" dt {n.dt_s:g} s"
    return f"{cfg.preset.name}, {n.integrator}{tol}"


# --------------------------------------------------------------------------- 1. rates


def _fit(cfg, **kw):
    try:
        r = corner_release_rate(config=cfg, **kw)
        return {"rate": r.rate, "stderr": r.stderr, "fit_range": list(r.fit_range), "drift": r.drift,
                "status": r.status, "error": None}
    except ValueError as e:
        return {"rate": None, "stderr": None, "error": str(e)}


def rates(ctx: Context) -> dict:
    out = {"balance": {p: corner_balance(preset=p).as_dict() for p in ("seed", "physical")}}
    phis = ctx.pick((0.3, 1.3, 2.5, 3.7, 5.0), (0.3, 2.5))
    # physical: at rest, 1e-10 rad; fit from 1e4× the start (the stable directions gone: at 100× they still
    # bias the rate by 6e-6 of it) to 1e-3 rad; alternatives: another start, a 10× tighter tolerance
    cfg = config(PHYSICAL)
    main = [_fit(cfg, tilt0=1e-10, start=1e4, saturation=1e-3, phi=f) for f in phis]
    # the numerics: the output step caps the sub-steps, so the step cap and the tolerance are varied together
    caps = ctx.pick(STEP_CAPS, STEP_CAPS[-1:])
    numerics = [{"dt_s": dt, "tol": tol, **_fit(config({**PHYSICAL, "tol": tol, "dt_s": dt}), tilt0=1e-10, start=1e4,
                                                 saturation=1e-3, phi=phis[0])} for dt, tol in caps]
    # the fit range: its end (the start fixed at 1e4 × tilt0, where the stable directions have decayed) and its start
    ends = _range_scan_fit(cfg, [(1e-6, e) for e in FIT_ENDS], phis[0], reference=FIT_ENDS.index(1e-3))
    starts = _range_scan_fit(cfg, [(1e-5, 1e-3), (1e-6, 1e-3)], phis[0], reference=1)
    spin = _fit(cfg, tilt0=1e-7, start=100.0, saturation=1e-3, phi=phis[0], spin_ratio=1.0)
    early = _fit(cfg, tilt0=1e-8, start=100.0, saturation=1e-3, phi=phis[0])  # the stable directions not gone yet
    out["physical"] = _summary(main, numerics, ends, starts, out["balance"]["physical"]["rate"],
                               model=_model_text(PHYSICAL), spin=spin, n_directions=len(main),
                               early_start_bias=(early["rate"] - out["balance"]["physical"]["rate"])
                               / out["balance"]["physical"]["rate"])
    # the seed force law, converged: released turning (its friction has no direction at rest); the tilt's
    # growth is linear in the amplitude's slip correction, so two saturations give the zero-amplitude rate
    cfg = config(SEED_CONVERGED)
    t0 = ctx.pick(1e-6, 1e-4)
    lo = [_fit(cfg, tilt0=t0, start=30.0, saturation=ctx.pick(1e-3, 1e-2), phi=f, spin_ratio=1.0)
          for f in phis[:2]]
    hi = _fit(cfg, tilt0=t0, start=30.0, saturation=ctx.pick(3e-3, 3e-2), phi=phis[0], spin_ratio=1.0)
    out["seed_converged"] = _extrapolated(lo, hi, ctx.pick((1e-3, 3e-3), (1e-2, 3e-2)),
                                          out["balance"]["seed"]["rate"], model=_model_text(SEED_CONVERGED),
                                          tilt0=t0)
    # the seed force law at rest: the adaptive integrator does not start; the program's step kicks it
    rest = corner_release(config(STUDY_CONVERGED), 1e-8, phis[0], t_max_s=0.05)
    out["seed_converged"]["at_rest"] = {"model": _model_text(STUDY_CONVERGED), "status": rest.status.label,
                                        "steps": rest.steps,
                                        "substeps": int(sum(rest.substeps.values()))}
    disc = config(SEED_DISCRETE)
    roll = corner_release(disc, 1e-8, phis[0], t_max_s=1.0, record=Record(states=True))
    tilt, az = corner_tilt(roll.trace.node_offsets[roll.trace.written])
    k = int(np.argmax(tilt > 0.03)) if (tilt > 0.03).any() else len(tilt) - 1
    out["seed_discrete"] = {"model": _model_text(SEED_DISCRETE), "tilt0": 1e-8, "tilt_after": [float(v) for v in
                            tilt[:6]], "fall_azimuth": float(az[k]), "phi": phis[0],
                            "fall_turn": abs(math.remainder(float(az[k]) - phis[0], 2 * math.pi)),
                            "fit": _fit(disc, tilt0=1e-8, start=5e5, saturation=0.03, phi=phis[0])}
    ctx.log(f"rates: physical {out['physical']['rate']:.6f} ± {out['physical']['error']:.1e} "
            f"(analytic {out['physical']['analytic']:.6f}); seed converged {out['seed_converged']['rate']:.4f} ± "
            f"{out['seed_converged']['error']:.1e} (rigid {out['seed_converged']['analytic']:.4f})")
    return out


def _range_scan_fit(cfg, ranges, phi: float, *, reference: int) -> dict:
    """The physical corner rate fitted over nested tilt ranges (rad) of one release at 1e-10 rad (its start a
    multiple of the start tilt): :func:`~dicetrace.analysis.robustness.range_scan` of the fit's range."""

    def fit(lo, hi):
        r = _fit(cfg, tilt0=1e-10, start=lo / 1e-10, saturation=hi, phi=phi)
        if r["rate"] is None:
            raise ValueError(r["error"])
        return r["rate"]

    return range_scan(fit, ranges, reference=reference).as_dict()


def _summary(main: list, numerics: list, ends: dict, starts: dict, analytic: float, **extra) -> dict:
    """The physical corner rate and its error budget: the mean over directions with the spread over them (stat; a
    regression's standard error of a clean exponential is rounding, not an error, and is left out), the shift when
    the step cap and the tolerance change (numerics), and the fit range's one-sided systematic (the end and the
    start of the fit moved); the difference from the analytic root in σ of the side it lies on."""
    r = np.array([m["rate"] for m in main if m["rate"] is not None], dtype=float)
    mean = float(r.mean())
    stat = float(r.std(ddof=1) / math.sqrt(len(r))) if len(r) > 1 else math.nan
    shifts = [m["rate"] - main[0]["rate"] for m in numerics if m["rate"] is not None]
    num = float(max((abs(v) for v in shifts), default=0.0))
    lo = float(max(ends["syst_lo"], starts["syst_lo"]))
    hi = float(max(ends["syst_hi"], starts["syst_hi"]))
    err_lo, err_hi = math.sqrt(stat**2 + num**2 + lo**2), math.sqrt(stat**2 + num**2 + hi**2)
    side = err_lo if analytic < mean else err_hi
    return {"runs": main, "numerics": numerics, "fit_ends": ends, "fit_starts": starts, "rate": mean, "stat": stat,
            "numerics_syst": num, "range_syst_lo": lo, "range_syst_hi": hi, "error": max(err_lo, err_hi),
            "error_lo": err_lo, "error_hi": err_hi, "analytic": analytic, "difference": mean - analytic,
            "sigmas": one_sided_z(mean, stat, math.hypot(num, lo), math.hypot(num, hi), analytic),
            "relative": (mean - analytic) / analytic, "range_syst_relative": max(lo, hi) / analytic,
            "error_side": side, "max_drift": float(max(m["drift"] for m in main)), **extra}


def _extrapolated(lo: list, hi: dict, sats, analytic: float, **extra) -> dict:
    r = np.array([m["rate"] for m in lo if m["rate"] is not None], dtype=float)
    a = float(r.mean())
    slope = (hi["rate"] - lo[0]["rate"]) / (sats[1] - sats[0])
    zero = lo[0]["rate"] - slope * sats[0] + (a - lo[0]["rate"])
    stat = math.hypot(float(r.std(ddof=1)) / math.sqrt(len(r)) if len(r) > 1 else 0.0,
                      max(m["stderr"] for m in lo))
    err = math.sqrt(stat**2 + (0.5 * (a - zero)) ** 2)
    return {"runs": lo, "high": hi, "saturations": list(sats), "rate_at_smallest": a, "rate": zero, "error": err,
            "analytic": analytic, "difference": zero - analytic, "sigmas": (zero - analytic) / err if err else None,
            "relative": (zero - analytic) / analytic, "drift": float(np.mean([m["drift"] for m in lo])),
            "drift_rigid": math.atan(1.0), **extra}


# --------------------------------------------------------------------------- 2. face maps


def face_maps(ctx: Context) -> tuple[dict, dict]:
    n_phi = ctx.pick(72, 12)
    phis = np.linspace(0.0, 2 * math.pi, n_phi, endpoint=False)
    out, plot = {}, {}
    for model, rings in RINGS.items():
        cfg = config(MODEL_OPTS[model])
        rows = []
        for tilt, ratio in (rings if not ctx.quick else rings[:2]):
            t0 = time.perf_counter()
            labels = face_map(cfg, [tilt], phis, spin_ratio=ratio)[0]
            borders = sector_boundaries(cfg, tilt, spin_ratio=ratio, tol=1e-9, phis=phis, labels=labels.tolist())
            # every edge's and every face's direction is a mirror line of the balance; a release turning at
            # ratio·λ·tilt leaves along φ + atan(ratio) (rigid pivot), so its borders move back by that
            kinds = [("edge", e) for e in EDGE_AZIMUTHS] + [("face", f) for f in FACE_AZIMUTHS.values()]
            for b in borders:
                kind, e = min(kinds, key=lambda k: abs(math.remainder(b["phi"] - k[1] + math.atan(ratio),
                                                                      2 * math.pi)))
                b["symmetry"], b["nearest_symmetry"] = kind, math.fmod(e - math.atan(ratio) + 2 * math.pi, 2 * math.pi)
                b["offset"] = math.remainder(b["phi"] - b["nearest_symmetry"], 2 * math.pi)
            faces = sorted({int(v) for v in labels.tolist()})
            rows.append({"tilt": tilt, "spin_ratio": ratio, "labels": labels.tolist(), "faces": faces,
                         "on": sorted({b["symmetry"] for b in borders}),
                         "n_borders": len(borders), "borders": borders,
                         "max_offset": max((abs(b["offset"]) for b in borders), default=None),
                         "max_error": max((b["error"] for b in borders), default=None),
                         "wall_s": time.perf_counter() - t0})
            plot[(model, tilt, ratio)] = labels
        out[model] = {"model": _model_text(MODEL_OPTS[model]), "rings": rows}
        ctx.log(f"face map {model}: " + "; ".join(f"{r['tilt']:g}/{r['spin_ratio']:g}: {r['faces']} "
                                                   f"{r['n_borders']} borders" for r in rows))
    return {"n_phi": n_phi, "phis": phis.tolist(), "models": out}, plot


# --------------------------------------------------------------------------- 3. triple points


def _thrower():
    """``throw(x, y)``: the seed-slice throw at (x, y) in the hunt's model, its outcome and closest approach to a
    corner balance."""

    hunt_cfg = config(HUNT_MODEL)
    cb = corner_balance(config=hunt_cfg)

    def throw(x, y):
        ic = seed_slice(np.array([x]), np.array([y]))[0]
        roll = simulate(ic, config=hunt_cfg, record=Record(states=True))
        return {"x": x, "y": y, "outcome": roll.outcome, "status": roll.status.label,
                **corner_distance(roll.trace, cb.rate, cb.d, cb.inertia)}

    return throw


def triple_points(ctx: Context) -> tuple[dict, dict]:
    hunt_cfg = config(HUNT_MODEL)
    cb = corner_balance(config=hunt_cfg)
    throw = _thrower()
    classify = classify_on_slice("seed", config=hunt_cfg)
    independent = {k: classify_on_slice("seed", config=config(v)) for k, v in INDEPENDENT.items()}
    res = ctx.res(161, 17)
    n_cand = ctx.pick(16, 1)
    tol = ctx.pick(1e-11, 1e-6)
    radii = RADII if not ctx.quick else RADII[:2]
    maps, plot, points = [], {}, []

    for w in (WINDOWS if not ctx.quick else WINDOWS[:1]):
        (x0, x1), (y0, y1) = window_ranges(w)
        width = x1 - x0
        s = ctx.sample(w, res, **MAP_MODEL)
        cert = certify_map(w, res, config=config(MAP_MODEL), base=s.labels, rng=int(ctx.rng.integers(2**31)))
        ctx.n_throws += 2 * s.labels.size
        radius, share = ctx.pick(4, 2), ctx.pick(0.15, 0.0)
        cand = clean_junctions(s.labels, radius=radius, min_share=share)
        pick = ctx.rng.permutation(len(cand))[:n_cand]
        ax, ay = s.axes
        hx, hy = ax[1] - ax[0], ay[1] - ay[0]
        n0 = classify.n_evals
        for k in pick:
            i, j = cand[k]
            t0 = time.perf_counter()
            row = {"window": w, "box": [int(i), int(j)], "map_labels": sorted({int(v) for v in
                                                                            s.labels[i:i + 2, j:j + 2].ravel()})}
            row.update(refine_triple(classify, (ax[i] + hx / 2, ay[j] + hy / 2), 1.5 * max(hx, hy), tol=tol))
            if row["status"] == "vertex":
                row["circles"] = [circle_sectors(classify, (row["x"], row["y"]), r * width, n=ctx.pick(24, 12))
                                  for r in radii]
                row["three_on_every_circle"] = all(c["three_sectors"] for c in row["circles"])
                row["throw"] = throw(row["x"], row["y"])
                row["reproduced"] = reproduce(ctx, row, width, {"hunt": classify, **independent}, tol)
            row["wall_s"] = time.perf_counter() - t0
            points.append(row)
            ctx.log(f"{w} box {i},{j}: {row['status']} {row.get('labels')} "
                    + (f"three sectors on every circle: {row['three_on_every_circle']}, D_min "
                       f"{row['throw']['d_min']:.3g}" if row["status"] == "vertex" else ""))
        # controls: random throws in the window, and throws on two-face borders (bisected between grid neighbours)
        rnd = [throw(float(ctx.rng.uniform(x0, x1)), float(ctx.rng.uniform(y0, y1)))
               for _ in range(ctx.pick(24, 2))]
        borders = [throw(*p) for p in _border_points(classify, s, ctx, ctx.pick(12, 2))]
        maps.append({"window": w, "res": res, "width": width, "n_candidates": int(len(cand)), "radius": radius,
                     "min_share": share,
                     "n_hunted": int(len(pick)), "certificate": cert.tightened.as_dict(), "floor": cert.floor.as_dict(),
                     "converged": converged_verdict(cert), "hunt_evals": classify.n_evals - n0,
                     "random": rnd, "border": borders})
        plot[w] = s
    ctx.n_throws += classify.n_evals + sum(c.n_evals for c in independent.values())
    return {"map_model": _model_text(MAP_MODEL), "hunt_model": _model_text(HUNT_MODEL), "tol": tol,
            "radii": list(radii), "rate": cb.rate, "maps": maps, "points": points,
            "independent": {k: _model_text(v) for k, v in INDEPENDENT.items()},
            "repro_radii": list(ctx.pick(REPRO_RADII, REPRO_RADII[:2])), "relocate_half": RELOCATE_HALF}, plot


def reproduce(ctx: Context, row: dict, width: float, classifiers: dict, tol: float) -> dict:
    """A located triple point seen by every integrator of ``classifiers`` (``"hunt"``: the one that located it):
    the faces on circles of the REPRO_RADII (fractions of the window's width) about it, the smallest radius down to
    which every integrator sees three sectors of the point's three faces
    (:func:`~dicetrace.analysis.robustness.common_scale`), and the point located again by each independent
    integrator from a box of half side RELOCATE_HALF × width about it, their spread against the hunt's box
    (:func:`~dicetrace.analysis.robustness.relocate`)."""
    radii = ctx.pick(REPRO_RADII, REPRO_RADII[:2])
    want = sorted(row["labels"])
    seen, faces = {}, {}
    n = ctx.pick(24, 8)
    ang = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    for name, cl in classifiers.items():
        faces[name], seen[name] = [], []
        for r in radii:  # the faces on the circle, in order (one batch; no bisection: which faces, not where)
            pts = np.column_stack([row["x"] + r * width * np.cos(ang), row["y"] + r * width * np.sin(ang)])
            runs = arcs([int(v) for v in np.asarray(cl(pts)).ravel()])
            f = [int(a[0]) for a in runs]
            faces[name].append(f)
            seen[name].append(len(f) == 3 and sorted(f) == want)
    points = {"hunt": (row["x"], row["y"])}
    found = {}
    for name, cl in classifiers.items():
        if name == "hunt":
            continue
        r = refine_triple(cl, (row["x"], row["y"]), RELOCATE_HALF * width, tol=tol)
        found[name] = {k: r.get(k) for k in ("status", "x", "y", "size", "labels", "evals")}
        points[name] = (r["x"], r["y"]) if r["status"] == "vertex" and sorted(r["labels"]) == want else None
    rel = relocate(points, reference="hunt", box=row["size"])
    scale = common_scale(radii, seen, reference="hunt", require=True)
    return {"radii": list(radii), "faces": faces, "three_sectors": seen, "reproducible_radius": scale,
            "relocated": found, "relocation": rel.as_dict(),
            "spread_over_width": rel.spread / width if math.isfinite(rel.spread) else None}


def _border_points(classify, s, ctx: Context, n: int) -> list[tuple[float, float]]:
    """Points on two-face borders: random horizontal grid neighbours of two different faces, bisected to 1e-12."""
    g = s.labels
    ax, ay = s.axes
    ii, jj = np.nonzero((g[:-1] != g[1:]) & (g[:-1] > 0) & (g[1:] > 0))
    out = []
    for k in ctx.rng.permutation(len(ii))[:n]:
        i, j = int(ii[k]), int(jj[k])
        a, b, la = float(ax[i]), float(ax[i + 1]), int(g[i, j])
        while b - a > 1e-12:
            m = 0.5 * (a + b)
            if int(classify(np.array([[m, ay[j]]]))[0]) == la:
                a = m
            else:
                b = m
        out.append((0.5 * (a + b), float(ay[j])))
    return out


def rerender(out, options: Options = Options(), *, remeasure: bool = False):
    """Redraw the figures and tables of a finished run in ``out`` without simulating a map (the maps from
    ``out/cache``; RuntimeError if one is not there), refresh the verdict from the stored numbers, and rewrite the
    JSON.  ``remeasure``: the throws' closest approaches to a corner balance computed again from their stored
    points with the current :func:`~dicetrace.analysis.corner_slice.corner_distance` (a pure function of the
    point: the same numbers a new run gives); its time is added to ``wall_s`` and kept in ``remeasure_s``."""

    out = Path(out)
    path = out / "results" / f"{NAME}.json"
    R = json.loads(path.read_text())
    ctx = Context(NAME, options, out / "cache")
    maps = {m["window"]: ctx.sample(m["window"], m["res"], **MAP_MODEL) for m in R["triple"]["maps"]}
    if ctx.n_throws:
        raise RuntimeError(f"{ctx.n_throws} throws were not in {out / 'cache'}: not the run's grids")
    if remeasure:
        t0 = time.perf_counter()
        throw = _thrower()
        for p in R["triple"]["points"]:
            if "throw" in p:
                p["throw"] = throw(p["x"], p["y"])
        for m in R["triple"]["maps"]:
            m["random"] = [throw(t["x"], t["y"]) for t in m["random"]]
            m["border"] = [throw(t["x"], t["y"]) for t in m["border"]]
        R["remeasure_s"] = time.perf_counter() - t0
        R["wall_s"] += R["remeasure_s"]
    fm = {(model, r["tilt"], r["spin_ratio"]): np.asarray(r["labels"])
          for model, v in R["face_maps"]["models"].items() for r in v["rings"]}
    R["triple"]["reproducibility"] = reproducibility(R["triple"]["points"])
    R["verdict"] = verdict(R)
    output = Output(out)
    render(Computed(R, {"face_maps": fm, "maps": maps}), output)
    R["figures"], R["tables"] = output.figures, output.tables
    write_json(path, R)
    return path


def reproducibility(points: list) -> dict:
    """Over the located points re-examined by the independent integrators (:func:`reproduce`): how many every
    integrator found again with the same faces, the largest and smallest spread of the points (fractions of the
    window's width), and the coarsest and finest radius down to which every integrator sees the three faces."""
    rp = [p["reproduced"] for p in points if p.get("reproduced")]
    spreads = [r["spread_over_width"] for r in rp if r["spread_over_width"] is not None]
    radii = [r["reproducible_radius"] for r in rp if r["reproducible_radius"] is not None]
    return {"n_points": len(rp), "n_found_by_all": sum(all(r["relocation"]["found"]) for r in rp),
            "spread_max": max(spreads, default=None), "spread_min": min(spreads, default=None),
            "radius_coarsest": max(radii, default=None), "radius_finest": min(radii, default=None),
            "n_without_common_radius": sum(r["reproducible_radius"] is None for r in rp),
            "n_with_common_radius": sum(r["reproducible_radius"] is not None for r in rp),
            "largest_radius": max((max(r["radii"]) for r in rp), default=None),
            "box_max": max((p["size"] for p in points if p.get("reproduced")), default=None)}


def compute(ctx: Context) -> Computed:
    rate = rates(ctx)
    fm, plot_fm = face_maps(ctx)
    tp, plot_tp = triple_points(ctx)
    tp["reproducibility"] = reproducibility(tp["points"])
    results = {"rates": rate, "face_maps": fm, "triple": tp}
    results["verdict"] = verdict(results)
    return Computed(results, {"face_maps": plot_fm, "maps": plot_tp})
