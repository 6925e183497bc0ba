"""Study p (onecell_converged): one cell or many, repetition and topology on the converged die (writeup 5.1, 5.5, 5.7).

Sections c, d and k5 asked these questions of the discrete 1 ms die; section l says they were not redone with a
converged integrator.  Here they are, on the ``physical`` preset integrated with ``contact-tsit5`` at a *uniform*
tolerance of 2·10⁻⁹ (no loosening over the throw: these are outcome maps, but the certificate must reach 0.99):

1. **One cell or many** (:func:`~dicetrace.analysis.onecell.join_counts`): 3-D stacks of the seed3 slice over three
   small windows of home (side 3·10⁻³, chosen before any map was drawn, equal spacing on the three axes), in a
   resolution series 16³ → 24³ → 32³ → 48³ → 64³; the 2-D cells of the z = 0 slice covering at least 0.5 % of it, and the
   fraction of them that share a 3-D cell with another 2-D cell of the slice, pooled over the windows, with a
   binomial error; :func:`~dicetrace.analysis.onecell.resolution_verdict` says whether it has stopped moving.
2. **Certificates**: at every level a random subset of the stacks' nodes is integrated again at a tenth of the
   tolerance and by an independent integrator (``contact-dop853``, an order-8 pair, at 10⁻¹⁰); "converged" where both
   agree on at least 0.99 of the nodes, else "statistics only".
3. **Period vectors** (:func:`~dicetrace.analysis.repetition.period_bootstrap`): the border-density texture of the
   zoom-out map (as section c) and its period vectors, each with a block-bootstrap error (the map cut into 6 × 6
   tiles, resampled), and the same map's certificate.
4. **Topology within one cell**: the first window's z = 0 slice at 32², 64², 96², its largest outcome cell, and its
   sub-cells by contact sequence (:func:`~dicetrace.analysis.prefixes.subcell_stats`).  The batch summaries record
   the contact set at the end of every output step, so the output step is taken 100 times shorter than the
   program's (10 µs): contact events are then located to 10 µs, and the sequences are compared with the same throws
   at 1 µs (exactness) and at the 1 ms steps (the sampling of sections d and k6).  Sub-cells are counted for the raw
   sequence and for sequences without the sets shorter than 0.1 ms and 1 ms (penalty micro-bounces).  The same maps
   are also run with **exact contact events** (``simulate_batch(..., record=Record.events_only())``: every set
   inside the integrator's sub-steps, located where nodes cross the ground, at the program's 1 ms output step), their
   sub-cells counted alike, and the events of the checked throws compared with the sampled sequences and with the
   events at a 10 µs output step.

The figures and tables are drawn by :mod:`dicetrace.studies.study_onecell_converged_render`.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from dicetrace.analysis.agreement import agreement
from dicetrace.analysis.cells import cells_table, label_cells
from dicetrace.analysis.onecell import join_counts, resolution_verdict
from dicetrace.analysis.prefixes import coarse_grain, subcell_stats
from dicetrace.analysis.repetition import find_periods, label_autocorrelation, off_centre_max, period_bootstrap, \
    texture_labels
from dicetrace.analysis.simulator import resolve_slice, run_on_slice, window_points
from dicetrace.params import make_config
from dicetrace.simulate import Record, set_to_text, simulate_batch
from dicetrace.status import Status
from dicetrace.studies.context import Computed, Context, Output, write_json
from dicetrace.studies.study_onecell_converged_render import render as _render
from dicetrace.studies.study_onecell_converged_render import join_figure, verdicts
from dicetrace.studies.text import CONVERGED_MIN

NAME = "onecell_converged"
#: The model and numerics of every map here (make_config options), the tightened and the independent ones.
MODEL = {"preset": "physical", "tol": 2e-9, "tol_growth": 0.0}
TIGHT = {"preset": "physical", "tol": 2e-10, "tol_growth": 0.0}
INDEPENDENT = {"preset": "physical", "integrator": "contact-dop853", "tol": 1e-10, "tol_growth": 0.0}
#: Side of the stacks' windows (slice units) and their lower-left corners in home (fixed before any map was drawn).
WIDTH = 3e-3
CORNERS = ((0.05, 0.05), (0.02, 0.02), (0.08, 0.03))
#: Nodes per axis of the stacks (full, quick).
LEVELS, QUICK_LEVELS = (16, 24, 32, 48, 64), (6, 8, 10)
#: The 2-D cells counted: at least this share of the slice's nodes.
MIN_AREA = 0.005
#: Stack nodes per window and level re-integrated for the certificates (full, quick).
N_CERT = (400, 12)
#: The repetition map: window and resolution (full, quick).
PERIOD_WINDOW, PERIOD_RES = "zoom-out", (251, 25)
#: Topology within a cell: resolutions (full, quick), output steps (s) of the sequences, the exactness check's and the
#: program's, the shortest sets kept (s; 0: the raw sequence), and the throws checked (full, quick).
SEQ_RES, QUICK_SEQ_RES = (32, 64, 96), (8, 10)
SEQ_DT, EXACT_DT, PROGRAM_DT = 1e-5, 1e-6, 1e-3
MIN_SET_S = (0.0, 1e-4, 1e-3)
#: Output step of the exact-event runs (the program's: the events are exact whatever it is).
EVENTS_DT = PROGRAM_DT
N_EXACT = (100, 3)


def _cfg(opts: dict, **extra):
    o = dict(opts)
    return make_config(o.pop("preset"), **o, **extra)


def model_text(opts: dict) -> str:
    c = _cfg(opts).numerics
    return f"physical, {c.integrator} tol {c.tol:g} uniform"


def _certify(ctx: Context, slice_spec, points: np.ndarray, labels: np.ndarray, n: int) -> dict:
    """The map's labels at ``n`` random points against the tightened and the independent integrators."""
    pick = ctx.rng.choice(len(points), size=min(n, len(points)), replace=False)
    pts, base = points[pick], np.asarray(labels).ravel()[pick]
    out = {}
    for key, opts in (("tightened", TIGHT), ("independent", INDEPENDENT)):
        out[key] = run_on_slice(pts, slice_spec, config=_cfg(opts)).outcome
        ctx.n_throws += len(pts)
    return {"base": base, **out}


def _certificate(parts: list[dict]) -> dict:
    base = np.concatenate([p["base"] for p in parts])
    t = agreement(base, np.concatenate([p["tightened"] for p in parts]))
    i = agreement(base, np.concatenate([p["independent"] for p in parts]))
    cert = min(t.fraction, i.fraction)
    return {"tightened": t.as_dict(), "independent": i.as_dict(), "certificate": cert,
            "word": "converged" if cert >= CONVERGED_MIN else "statistics only"}


# --------------------------------------------------------------------------- 1-2. stacks


def stacks(ctx: Context) -> tuple[dict, dict]:
    levels = ctx.pick(LEVELS, QUICK_LEVELS)
    corners = CORNERS if not ctx.quick else CORNERS[:2]
    rows, plot = [], {}
    for n in levels:
        t0 = time.perf_counter()
        per, cert_parts = [], []
        for c, (x0, y0) in enumerate(corners):
            win = ((x0, x0 + WIDTH), (y0, y0 + WIDTH), (0.0, WIDTH))
            s = ctx.sample(win, n, slice_spec="seed3", **MODEL)
            jc = join_counts(s.labels, min_area=MIN_AREA)
            _, n3 = label_cells(s.labels)
            per.append({"window": c, "corner": [x0, y0], **jc, "n_cells_3d": int(n3),
                        "unsettled": int((s.labels < 1).sum())})
            pts, _, _ = window_points(win, n)
            cert_parts.append(_certify(ctx, "seed3", pts, s.labels, ctx.pick(N_CERT[0], N_CERT[1])))
            plot[(c, n)] = s.labels
        nc, nj = sum(p["n_cells"] for p in per), sum(p["n_joined"] for p in per)
        f = nj / nc if nc else math.nan
        row = {"res": n, "nodes": n ** 3, "n_cells": nc, "n_joined": nj, "fraction": f,
               "stderr": math.sqrt(f * (1 - f) / nc) if nc else math.nan,
               "area_fraction": float(np.average([p["area_fraction"] for p in per if p["n_cells"]],
                                                 weights=[p["n_cells"] for p in per if p["n_cells"]]))
               if nc else math.nan,
               "windows": per, "certificate": _certificate(cert_parts), "wall_s": time.perf_counter() - t0}
        rows.append(row)
        ctx.log(f"stacks {n}³: {nj}/{nc} cells joined ({f:.3f}), certificate {row['certificate']['certificate']:.4f}")
    verdict = resolution_verdict([r["fraction"] for r in rows], [r["n_cells"] for r in rows])
    enough = len(rows) >= 3 and all(r["n_cells"] >= 10 for r in rows[-3:])
    if verdict == "converged" and not enough:
        verdict = "undetermined"
    certs = [r["certificate"]["certificate"] for r in rows]
    word = "converged" if min(certs) >= CONVERGED_MIN else "statistics only"
    return {"levels": rows, "corners": [list(c) for c in corners], "width": WIDTH, "min_area": MIN_AREA,
            "verdict": verdict, "certificate_min": min(certs), "certificate_word": word,
            "last": rows[-1], "first": rows[0]}, plot


# --------------------------------------------------------------------------- 3. periods


def periods(ctx: Context) -> tuple[dict, dict]:
    res = ctx.res(*PERIOD_RES)
    s = ctx.sample(PERIOD_WINDOW, res, **MODEL)
    g, h = s.labels, s.spacing
    sigma = max(1.0, 0.015 * (res - 1))
    tex = texture_labels(g, sigma)
    found = find_periods(tex, spacing=h, min_strength=0.1)
    rows = []
    for r in found.itertuples():
        b = period_bootstrap(tex, (int(r.di), int(r.dj)), tiles=6, n_boot=ctx.pick(200, 20),
                             rng=int(ctx.rng.integers(2**31)))
        rows.append({"di": int(r.di), "dj": int(r.dj), "strength": float(r.strength),
                     "dx": b["di"] * h[0], "dy": b["dj"] * h[1], "dx_stderr": b["di_stderr"] * h[0],
                     "dy_stderr": b["dj_stderr"] * h[1], "length": float(math.hypot(b["di"] * h[0], b["dj"] * h[1])),
                     "interior": b["interior"], "interior_fraction": b["interior_fraction"], "n_boot": b["n_boot"]})
    c_out, c_tex = label_autocorrelation(g), label_autocorrelation(tex)
    pts, _, _ = window_points(PERIOD_WINDOW, res)
    cert = _certificate([_certify(ctx, "seed", pts, g, ctx.pick(1000, 20))])
    cs = cells_table(g)
    ctx.log(f"periods {PERIOD_WINDOW} {res}²: {len(rows)} texture periods, certificate {cert['certificate']:.4f}")
    return {"window": PERIOD_WINDOW, "res": res, "sigma_nodes": sigma, "spacing": h[0], "periods": rows,
            "n_periods": len(rows),
            "outcome_offcentre_max_corr": off_centre_max(c_out, int(0.05 * res)),
            "texture_offcentre_max_corr": off_centre_max(c_tex, int(0.05 * res)),
            "frac_nodes_in_singletons": float(cs.loc[cs["size"] == 1, "size"].sum() / g.size),
            "certificate": cert}, {"map": s, "c_tex": c_tex}


# --------------------------------------------------------------------------- 4. topology within a cell


def _texts(b) -> dict:
    """Every throw's contact sequence, raw and without the sets shorter than each of :data:`MIN_SET_S`.

    Durations in whole output steps for sampled sequences (at least one step), in seconds for exact contact events
    (``b`` run with ``record=Record.events_only()``: its ``set_times``)."""
    dt = b.config.numerics.dt_s
    exact = b.set_times is not None
    out = {}
    for m in MIN_SET_S:
        if m == 0.0:
            out[m] = np.array(b.contact_sequences(), dtype=object)
            continue
        starts = b.set_times if exact else b.set_steps
        shortest = m if exact else max(1, int(round(m / dt)))
        seqs = []
        for i in range(len(b)):
            a, e = b.set_offsets[i], b.set_offsets[i + 1]
            end_at = float(b.steps[i]) * dt if exact else int(b.steps[i])
            cg = coarse_grain(b.sets[a:e], starts[a:e], end_at, min_steps=shortest)
            seqs.append("-".join(set_to_text(v) for v in cg))
        out[m] = np.array(seqs, dtype=object)
    return out


def _sampled(b, factor: int) -> np.ndarray:
    """Every throw's raw contact sequence as a step ``factor`` times longer would sample the same trajectory: the set
    held at every ``factor``-th output step, repeats merged (the sequence starts with the empty set)."""
    out = []
    for i in range(len(b)):
        a, e = b.set_offsets[i], b.set_offsets[i + 1]
        sets, steps = b.sets[a:e], b.set_steps[a:e]
        ticks = np.arange(factor, int(b.steps[i]) + 1, factor)
        held = sets[np.searchsorted(steps, ticks, side="right") - 1] if len(ticks) else sets[:0]
        seq = [int(sets[0])]
        for v in held.tolist():
            if v != seq[-1]:
                seq.append(int(v))
        out.append("-".join(set_to_text(v) for v in seq))
    return np.array(out, dtype=object)


def _batch(ctx: Context, pts: np.ndarray, dt: float, *, events: bool = False):
    sl = resolve_slice("seed")
    b = simulate_batch(sl.to_ics(pts), config=_cfg(MODEL, dt_s=dt), l_convention=sl.l_convention,
                       record=Record.events_only() if events else None)
    ctx.n_throws += len(pts)
    return b


def _labels(b, shape) -> np.ndarray:
    return np.where(b.status_code == Status.SETTLED, b.outcome, -1).astype(np.int64).reshape(shape)


def _largest_cell(lab: np.ndarray):
    ids, _ = label_cells(lab)
    t = cells_table(lab)
    big = t.loc[t["size"].idxmax()]
    return big, ids == int(big["cell_id"])


def topology(ctx: Context) -> tuple[dict, dict]:
    x0, y0 = CORNERS[0]
    win = ((x0, x0 + WIDTH), (y0, y0 + WIDTH))
    rows, plot = [], {}
    for res in ctx.pick(SEQ_RES, QUICK_SEQ_RES):
        t0 = time.perf_counter()
        pts, shape, _ = window_points(win, res)
        b = _batch(ctx, pts, SEQ_DT)
        lab = _labels(b, shape)
        big, mask = _largest_cell(lab)
        texts = _texts(b)
        row = {"res": res, "cell_label": int(big["label"]), "cell_nodes": int(big["size"]),
               "cell_frac": float(big["size"] / lab.size), "by_min_set": []}
        for m in MIN_SET_S:
            st = subcell_stats(texts[m].reshape(shape), mask)
            row["by_min_set"].append({"min_set_s": m, **st})
        # the same map with exact contact events (its own outcome labels: a 1 ms output step bounds the sub-steps otherwise)
        be = _batch(ctx, pts, EVENTS_DT, events=True)
        lab_e = _labels(be, shape)
        big_e, mask_e = _largest_cell(lab_e)
        texts_e = _texts(be)
        row["events"] = {"dt_s": EVENTS_DT, "cell_label": int(big_e["label"]), "cell_nodes": int(big_e["size"]),
                         "cell_frac": float(big_e["size"] / lab_e.size),
                         "same_outcome_as_sampled": float(np.mean(lab_e == lab)),
                         "mean_events": float(np.mean(np.diff(be.set_offsets))),
                         "by_min_set": [{"min_set_s": m, **subcell_stats(texts_e[m].reshape(shape), mask_e)}
                                        for m in MIN_SET_S]}
        row["wall_s"] = time.perf_counter() - t0
        rows.append(row)
        plot[res] = (lab, mask, texts[0.0].reshape(shape))
        ctx.log(f"topology {res}²: cell of face {row['cell_label']} ({row['cell_frac']:.2f} of the window), "
                + ", ".join(f"≥{r['min_set_s']:g} s: {r['n_labels']} sequences, {r['n_subcells']} sub-cells"
                            for r in row["by_min_set"])
                + "; exact events: " + ", ".join(f"≥{r['min_set_s']:g} s: {r['n_subcells']} sub-cells"
                                                 for r in row["events"]["by_min_set"]))
    # exactness: throws of the finest cell at the 1 µs and at the program's 1 ms output step
    res = rows[-1]["res"]
    pts, shape, _ = window_points(win, res)
    lab, mask, _ = plot[res]
    inside = np.flatnonzero(mask.ravel())
    pick = np.sort(ctx.rng.choice(inside, size=min(ctx.pick(N_EXACT[0], N_EXACT[1]), len(inside)), replace=False))
    ref = _batch(ctx, pts[pick], SEQ_DT)
    base = _texts(ref)
    exact = {"n": int(len(pick)), "dt_s": SEQ_DT, "by_min_set": []}
    finer, coarser = _batch(ctx, pts[pick], EXACT_DT), _batch(ctx, pts[pick], PROGRAM_DT)
    tf, tc = _texts(finer), _texts(coarser)
    sampled = _sampled(ref, int(round(PROGRAM_DT / SEQ_DT)))
    exact["same_when_sampled_at_program_dt"] = float(np.mean(base[0.0] == sampled))
    exact["mean_sets_sampled_at_program_dt"] = float(np.mean([len(q.split("-")) for q in sampled]))
    for m in MIN_SET_S:
        exact["by_min_set"].append({
            "min_set_s": m, "same_at_exact_dt": float(np.mean(base[m] == tf[m])),
            "same_at_program_dt": float(np.mean(base[m] == tc[m])),
            "mean_sets": float(np.mean([len(q.split("-")) for q in base[m]])),
            "mean_sets_program_dt": float(np.mean([len(q.split("-")) for q in tc[m]]))})
    exact["same_outcome_exact_dt"] = float(np.mean(ref.outcome == finer.outcome))
    exact["same_outcome_program_dt"] = float(np.mean(ref.outcome == coarser.outcome))
    exact["exact_dt_s"], exact["program_dt_s"] = EXACT_DT, PROGRAM_DT
    # exact contact events of the same throws: at the program's output step and at 10 µs (the events do not depend on
    # the output step but through the sub-steps it bounds), against the sequences sampled at 10 µs and 1 µs
    ev, ev_fine = _batch(ctx, pts[pick], EVENTS_DT, events=True), _batch(ctx, pts[pick], SEQ_DT, events=True)
    te, tef = _texts(ev), _texts(ev_fine)
    exact["events"] = {"dt_s": EVENTS_DT, "fine_dt_s": SEQ_DT, "by_min_set": [
        {"min_set_s": m, "same_events_at_fine_dt": float(np.mean(te[m] == tef[m])),
         "same_as_sampled_seq_dt": float(np.mean(te[m] == base[m])),
         "same_as_sampled_exact_dt": float(np.mean(te[m] == tf[m])),
         "fine_same_as_sampled_exact_dt": float(np.mean(tef[m] == tf[m])),
         "mean_events": float(np.mean([len(q.split("-")) for q in te[m]]))} for m in MIN_SET_S],
        "same_outcome_fine_dt": float(np.mean(ev.outcome == ev_fine.outcome)),
        "same_outcome_as_sampled_seq_dt": float(np.mean(ev.outcome == ref.outcome))}
    ctx.log("exact events: " + ", ".join(
        f"≥{r['min_set_s']:g} s: {r['same_events_at_fine_dt']:.2f} same at 10 µs output, "
        f"{r['same_as_sampled_exact_dt']:.2f} as sampled at 1 µs" for r in exact["events"]["by_min_set"]))
    ctx.log("exactness: " + ", ".join(f"≥{r['min_set_s']:g} s: {r['same_at_exact_dt']:.2f} at 1 µs, "
                                      f"{r['same_at_program_dt']:.2f} at 1 ms" for r in exact["by_min_set"]))
    return {"window": [list(w) for w in win], "dt_s": SEQ_DT, "min_set_s": list(MIN_SET_S), "levels": rows,
            "exact": exact}, plot


def compute(ctx: Context) -> Computed:
    st, plot_st = stacks(ctx)
    per, plot_per = periods(ctx)
    top, plot_top = topology(ctx)
    results = {"model": model_text(MODEL), "tightened": model_text(TIGHT),
               "independent": f"physical, contact-dop853 tol {INDEPENDENT['tol']:g} uniform",
               "stacks": st, "periods": per, "topology": top}
    results["verdict"] = verdicts(results)
    return Computed(results, {"stacks": plot_st, "periods": plot_per, "topology": plot_top})


def render(c: Computed, out: Output) -> None:
    _render(c, out)


def rerender(out) -> Path:
    """Write the tables, the verdicts and the join figure of ``OUT/results/onecell_converged.json`` again from its
    numbers alone (no simulation, no number changed; the other figures, drawn from the grids, are kept as they are)."""
    path = Path(out) / "results" / f"{NAME}.json"
    R = json.loads(path.read_text())
    R["verdict"] = verdicts(R)
    output = Output(Path(out))
    render(Computed(R), output)
    join_figure(R, output)
    R["tables"] = output.tables
    R["figures"].update(output.figures)
    write_json(path, R)
    return path
