"""Study l (converged): converged maps beside the discrete ones: every measure of a map, side by side, with certificates.

For the windows home [0, .1]², zoom-out [0, 1]², more-out [0, 10]² and red
sea [1, 2]×[3.5, 4.5], one grid (201² in the full run) is simulated with
three models:

* ``discrete``: the program (``seed`` preset, semi-implicit Euler at
  dt = 1 ms), the model of sections a–i;
* ``converged``: the program's force law integrated to convergence
  (``seed`` with ``contact-adaptive`` at tol 1e-7);
* ``physical``: the ``physical`` preset with its own default integrator
  and tolerance (read from the preset, so a faster default is picked up).

``dicetrace analyze converged --integrator NAME --tol T`` overrides the
integrator and tolerance of the two converged models (not of ``discrete``).

Each map carries the convergence certificate of
:func:`~dicetrace.analysis.transient.certify_map` (agreement with the map
integrated 10× tighter, against the chaos floor: agreement under an IC move
of a tenth of the grid spacing; Wilson intervals and Cohen's κ). A map whose
certificate is below its floor, or whose agreement with the tighter map is
at chance (Cohen's κ within 3 standard errors of 0), is marked not
converged.

Then every measure of the report that applies to one map, per model: cells
(count, sizes), face fractions (block errors; χ² test of each model's face
counts against the discrete ones), boundary fraction, α by boxes, by grid
resolution and by random-pair perturbation, the boundary's dimension, the
basin entropies Sb and Sbb, the Wada merge test, settle-time statistics and
the escape rate κ, and the repetition measures (outcome autocorrelation,
texture period vectors) — with the measures the other studies use
(:func:`dicetrace.analysis.sweep.map_measures`,
:func:`dicetrace.analysis.cells.cell_stats`,
:func:`dicetrace.analysis.repetition.repetition_stats`,
:func:`dicetrace.analysis.settle.settle_stats`, :func:`dicetrace.analysis.agreement.face_stats`).

Which measures change between models is judged in
:mod:`dicetrace.studies.study_converged_changes`; the tables, answers and figures
are drawn by :mod:`dicetrace.studies.study_converged_render`.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np

from dicetrace.analysis import agreement
from dicetrace.analysis.agreement import face_stats
from dicetrace.analysis.cells import cell_stats
from dicetrace.analysis.repetition import repetition_stats
from dicetrace.analysis.settle import border_pairs, divergence_lambdas, fit_border, settle_stats
from dicetrace.params import make_config
from dicetrace.studies.context import Computed, Context, Options, Output, write_json
from dicetrace.studies.study_converged_changes import CHANGE_SIGMA, changes
from dicetrace.studies.study_converged_render import render, verdict_text

NAME = "converged"
WINDOWS = ("home", "zoom-out", "more-out", "red-sea")
#: The models, in the tables' column order.
MODEL_NAMES = ("discrete", "converged", "physical")
#: Borders of each map located for the settle-time divergence λ (full run).
BORDERS_FULL = 12


def models(integrator: str | None = None, tol: float | None = None) -> dict[str, dict]:
    """make_config options of each model: those of study j (transient), with the converged models' overrides."""
    from dicetrace.studies.study_transient import MODELS  # lazy: keeps `dicetrace --help` fast (it imports numba)

    out = {m: dict(MODELS[m]) for m in MODEL_NAMES}
    for m in ("converged", "physical"):
        if integrator is not None:
            out[m]["integrator"] = integrator
        if tol is not None:
            out[m]["tol"] = tol
    return out


def check_overrides(integrator: str | None = None, tol: float | None = None) -> None:
    """Refuse (ValueError) an integrator or tolerance that a converged model cannot run with, before any work."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # make_config's notes (a tolerance a fixed step ignores) belong to the run
        for opts in models(integrator, tol).values():
            model_config(opts)


def model_config(opts: dict):
    kw = dict(opts)
    return make_config(kw.pop("preset"), **kw)


def settle_divergence(ctx: Context, s, cfg) -> dict:
    """Section g's settle-time divergence T ≈ T0 − ln(d)/λ at borders of this map: λ over all fitted sides
    (mean ± se, median ± bootstrap se) and over the clean fits (r < −0.995)."""
    # lazy: keeps `dicetrace --help` fast (imports numba)
    from dicetrace.analysis.simulator import classify_on_slice, settle_on_slice

    classify, settle = classify_on_slice("seed", config=cfg), settle_on_slice("seed", config=cfg)
    dists = np.logspace(-11, -4, ctx.pick(22, 8))
    fits = []
    for pa, pb in border_pairs(s, ctx.pick(BORDERS_FULL, 2), ctx.rng):
        f, _ = fit_border(classify, settle, np.array(pa), np.array(pb), dists)
        fits.append(f)
    ctx.n_throws += classify.n_evals + settle.n_evals
    return divergence_lambdas(fits)


def measure_map(ctx: Context, window: str, model: str, opts: dict, res: int, ref=None) -> tuple[dict, object]:
    """Every map measure of one window and model, and its certificate: (numbers, the sample)."""
    from dicetrace.analysis.simulator import classify_on_slice  # lazy: keeps `dicetrace --help` fast (imports numba)
    from dicetrace.analysis.transient import certify_map, converged_verdict
    from dicetrace.studies.study_fractal import measures  # lazy: keeps `dicetrace --help` fast (it imports numba)

    cfg = model_config(opts)
    s = ctx.sample(window, res, **opts)
    g = s.labels
    cert = certify_map(window, res, config=cfg, base=g, rng=int(ctx.rng.integers(2**31)))
    ctx.n_throws += 2 * g.size
    classify = classify_on_slice("seed", config=cfg)
    row = measures(ctx, window, s, classify, perturb=True, wada_grid=False)
    ctx.n_throws += classify.n_evals
    cs = cell_stats(g)
    cs.pop("sizes")
    row.update(
        model=model, integrator=cfg.numerics.integrator, tol=cfg.numerics.tol, tol_growth=cfg.numerics.tol_growth,
        dt_s=cfg.numerics.dt_s,
        tight_integrator=cert.tight_config.numerics.integrator, tight_tol=cert.tight_config.numerics.tol,
        tight_dt_s=cert.tight_config.numerics.dt_s,
        certificate=cert.tightened.as_dict(), floor=cert.floor.as_dict(),
        above_floor=cert.converged, converged=converged_verdict(cert),
        cells=cs, settle=settle_stats(s), repetition=repetition_stats(s), divergence=settle_divergence(ctx, s, cfg),
        **face_stats(g, None if ref is None else ref.labels),
    )
    if ref is not None:
        row["agreement_with_discrete"] = agreement(g, ref.labels).as_dict()
    ctx.log(f"{window} {model}: certificate {cert.tightened.fraction:.3f} (floor {cert.floor.fraction:.3f}, "
            f"{verdict_text(row)}), {cs['n_cells']} cells, "
            f"α pert {row.get('alpha_pert', math.nan):.3f}, Sbb {row['Sbb']:.3f}")
    return row, s


def compute(ctx: Context) -> Computed:
    opts = models(ctx.options.integrator, ctx.options.tol)
    res = ctx.res(201, 21)
    by: dict = {}
    plot: dict = {}
    for w in WINDOWS:
        by[w] = {}
        ref = None
        for m in MODEL_NAMES:
            row, s = measure_map(ctx, w, m, opts[m], res, ref=ref)
            if m == "discrete":
                ref = s
            by[w][m] = row
            plot[(w, m)] = s
    summary = _summary(by)
    return Computed({"res": res, "windows": list(WINDOWS), "models": {m: {**opts[m], "integrator": by[WINDOWS[0]][m][
        "integrator"], "tol": by[WINDOWS[0]][m]["tol"], "tol_growth": by[WINDOWS[0]][m]["tol_growth"],
        "dt_s": by[WINDOWS[0]][m]["dt_s"]} for m in MODEL_NAMES},
        "by": by, "summary": summary, "change_sigma": CHANGE_SIGMA}, plot)


def _summary(by: dict) -> dict:
    """Ranges over the windows per model (for the answers table) and the certificates' verdicts.

    Also (re)writes each window's ``changes`` and ``changes_physical`` (:func:`changes`) into ``by``.
    """
    for w in WINDOWS:
        by[w]["changes"] = changes(by[w])
        by[w]["changes_physical"] = changes(by[w], "discrete", "physical")
    out: dict = {}
    for m in MODEL_NAMES:
        rows = [by[w][m] for w in WINDOWS]
        a = [r.get("alpha_pert") for r in rows if r.get("alpha_pert") is not None and math.isfinite(r["alpha_pert"])]
        d = [r["dim_mask"] for r in rows if r.get("dim_mask") is not None and math.isfinite(r["dim_mask"])]
        cert = [r["certificate"]["fraction"] for r in rows]
        out[m] = {
            "alpha_pert_min": min(a) if a else None, "alpha_pert_max": max(a) if a else None,
            "dim_mask_min": min(d) if d else None, "dim_mask_max": max(d) if d else None,
            "certificate_min": min(cert), "certificate_max": max(cert),
            "n_converged": sum(bool(r["converged"]) for r in rows), "n_maps": len(rows),
            "converged_windows": [w for w in WINDOWS if by[w][m]["converged"]],
        }
    out["changed"] = {w: [c["measure"] for c in by[w]["changes"] if c["changed"]] for w in WINDOWS}
    out["alpha_pert_change"] = _alpha_pert_change(by)
    return out


def _alpha_pert_change(by: dict) -> str:
    """How far α by perturbation moves from the discrete to the converged map in home and zoom-out, in words."""
    z = {w: next(c["z"] for c in by[w]["changes"] if c["key"] == "alpha_pert") for w in ("home", "zoom-out")}
    if any(v is None or not math.isfinite(v) for v in z.values()):
        return "(no error bar on one of them)"
    beyond = [w for w, v in z.items() if v > CHANGE_SIGMA]
    verdict = (f"not beyond the {CHANGE_SIGMA:g} σ threshold" if not beyond
               else f"beyond the {CHANGE_SIGMA:g} σ threshold in {' and '.join(beyond)}")
    return f"by {z['home']:.1f} and {z['zoom-out']:.1f} standard errors, {verdict}"


def retable(out) -> Path:
    """Write the tables of a finished run in ``out`` again from ``results/converged.json`` alone (no grid, no
    simulation, no number changed; the figures, drawn from the grids, are kept as they are)."""
    from dicetrace.studies.study_converged_render import changes_text, window_table

    path = Path(out) / "results" / f"{NAME}.json"
    results = json.loads(path.read_text())
    by, windows, models = results["by"], tuple(results["windows"]), tuple(results["models"])
    sigma = results.get("change_sigma", CHANGE_SIGMA)
    tables = dict(results.get("tables", {}))
    for w in windows:
        tables[f"window_{w}"] = window_table(by[w], models, sigma)
    tables["changes"] = changes_text(by, windows, sigma)
    results["tables"] = tables
    write_json(path, results)
    return path


def rerender(out, options: Options = Options()) -> Path:
    """Redraw the figures and tables of a finished run in ``out`` without simulating.

    Reads ``out/results/converged.json`` and the grids cached in
    ``out/cache`` (``options`` must be those of the run, for the cache keys),
    recomputes the summary, the changes and the tables from the stored
    numbers (and the repetition measures, a deterministic function of the
    cached grids), and rewrites the JSON. RuntimeError if a grid is not cached.
    """
    out = Path(out)
    path = out / "results" / f"{NAME}.json"
    results = json.loads(path.read_text())
    ctx = Context(NAME, options, out / "cache")
    opts = models(options.integrator, options.tol)
    plot = {(w, m): ctx.sample(w, results["res"], **opts[m]) for w in results["windows"] for m in MODEL_NAMES}
    if ctx.n_throws:
        raise RuntimeError(f"{ctx.n_throws} throws were not in {out / 'cache'}: not the run's grids")
    for (w, m), s in plot.items():  # a pure function of the cached grid: refreshed with the code
        results["by"][w][m]["repetition"] = repetition_stats(s)
    results["summary"] = _summary(results["by"])
    output = Output(out)
    render(Computed(results, plot), output)
    results["figures"], results["tables"] = output.figures, output.tables
    write_json(path, results)
    return path
