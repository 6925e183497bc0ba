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
   turning because its friction law has no direction at rest); error bars
   from the spread over directions, alternative fit ranges and a 10× tighter
   tolerance.  The program's own integrator (``seed``, semi-implicit Euler)
   is run too.
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
   throws and throws on two-face borders.

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
from dicetrace.analysis.corner_slice import circle_sectors, clean_junctions, corner_distance, refine_triple
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
    alt_start = _fit(cfg, tilt0=1e-9, start=1e4, saturation=1e-3, phi=phis[0])
    alt_late = _fit(cfg, tilt0=1e-10, start=1e5, saturation=1e-3, phi=phis[0])
    alt_tol = _fit(config({**PHYSICAL, "tol": PHYSICAL["tol"] / 10}), tilt0=1e-10, start=1e4, saturation=1e-3,
                   phi=phis[0])
    spin = _fit(cfg, tilt0=1e-7, start=100.0, saturation=1e-3, phi=phis[0], spin_ratio=1.0)
    early = _fit(cfg, tilt0=1e-8, start=100.0, saturation=1e-3, phi=phis[0])  # the stable directions not gone yet
    out["physical"] = _summary(main, [alt_start, alt_late, alt_tol], out["balance"]["physical"]["rate"],
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


def _summary(main: list, alts: list, analytic: float, **extra) -> dict:
    r = np.array([m["rate"] for m in main if m["rate"] is not None], dtype=float)
    se = np.array([m["stderr"] for m in main if m["rate"] is not None], dtype=float)
    mean = float(r.mean())
    stat = float(math.hypot(r.std(ddof=1) / math.sqrt(len(r)) if len(r) > 1 else 0.0, float(se.max())))
    syst = [abs(a["rate"] - main[0]["rate"]) for a in alts if a["rate"] is not None]
    err = float(math.sqrt(stat**2 + sum(s**2 for s in syst)))
    return {"runs": main, "alternatives": alts, "rate": mean, "stat": stat, "syst": syst, "error": err,
            "analytic": analytic, "difference": mean - analytic, "sigmas": (mean - analytic) / err if err else None,
            "relative": (mean - analytic) / analytic, "max_drift": float(max(m["drift"] for m in main)), **extra}


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
    ctx.n_throws += classify.n_evals
    return {"map_model": _model_text(MAP_MODEL), "hunt_model": _model_text(HUNT_MODEL), "tol": tol,
            "radii": list(radii), "rate": cb.rate, "maps": maps, "points": points}, plot


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
    R["verdict"] = verdict(R)
    output = Output(out)
    render(Computed(R, {"face_maps": fm, "maps": maps}), output)
    R["figures"], R["tables"] = output.figures, output.tables
    write_json(path, R)
    return path


def compute(ctx: Context) -> Computed:
    rate = rates(ctx)
    fm, plot_fm = face_maps(ctx)
    tp, plot_tp = triple_points(ctx)
    results = {"rates": rate, "face_maps": fm, "triple": tp}
    results["verdict"] = verdict(results)
    return Computed(results, {"face_maps": plot_fm, "maps": plot_tp})
