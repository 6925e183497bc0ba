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
texture period vectors) — with the functions the other studies use
(:func:`dicetrace.studies.fractal.measures`,
:func:`dicetrace.studies.cells.cell_stats`, the repetition helpers).
"""

from __future__ import annotations

import math

import numpy as np

from pathlib import Path

from dicetrace.studies.context import Computed, Context, Options, Output
from dicetrace.studies.text import fmt, md_table, pm, tol_text

NAME = "converged"
WINDOWS = ("home", "zoom-out", "more-out", "red-sea")
#: The models, in the tables' column order.
MODEL_NAMES = ("discrete", "converged", "physical")
#: Borders of each map located for the settle-time divergence λ (full run).
BORDERS_FULL = 12
#: A difference between two models counts as a change beyond this many standard errors.
CHANGE_SIGMA = 3.0


def models(integrator: str | None = None, tol: float | None = None) -> dict[str, dict]:
    """make_config options of each model: those of study j (transient), with the converged models' overrides."""
    from dicetrace.studies.transient import MODELS

    out = {m: dict(MODELS[m]) for m in MODEL_NAMES}
    for m in ("converged", "physical"):
        if integrator is not None:
            out[m]["integrator"] = integrator
        if tol is not None:
            out[m]["tol"] = tol
    return out


def check_overrides(integrator: str | None = None, tol: float | None = None) -> None:
    """Refuse (ValueError) an integrator or tolerance that a converged model cannot run with, before any work."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # make_config's notes (a tolerance a fixed step ignores) belong to the run
        for opts in models(integrator, tol).values():
            model_config(opts)


def model_config(opts: dict):
    from dicetrace.params import make_config

    kw = dict(opts)
    return make_config(kw.pop("preset"), **kw)


def settle_stats(s) -> dict:
    """Settle-time statistics of a map: quantiles, border against interior, and the escape rate κ."""
    from dicetrace.analysis import boundary_mask, escape_rate

    t, g = s.t_settle_s, s.labels
    ok = g > 0
    tt = t[ok]
    border = boundary_mask(g) & ok
    inner = ~boundary_mask(g) & ok
    out = {
        "n_settled": int(ok.sum()), "n_unsettled": int((g == -1).sum()),
        "mean": float(tt.mean()), "mean_stderr": float(tt.std(ddof=1) / math.sqrt(len(tt))) if len(tt) > 1 else None,
        "median": float(np.median(tt)), "q90": float(np.quantile(tt, 0.9)), "max": float(tt.max()),
        "border_mean": float(t[border].mean()) if border.any() else None,
        "interior_mean": float(t[inner].mean()) if inner.any() else None,
    }
    try:
        k = escape_rate(tt, min_tail=10, censored_at=float(np.max(t)) if (g == -1).any() else None)
        out.update(kappa=k.kappa, kappa_stderr=k.stderr, kappa_t0=k.t0, kappa_t1=k.t1)
    except ValueError as e:
        out.update(kappa=None, kappa_stderr=None, kappa_error=str(e))
    return out


def settle_divergence(ctx: Context, s, cfg) -> dict:
    """Section g's settle-time divergence T ≈ T0 − ln(d)/λ at borders of this map: λ over all fitted sides
    (mean ± se, median ± bootstrap se) and over the clean fits (r < −0.995)."""
    from dicetrace.analysis.simulator import classify_on_slice, settle_on_slice
    from dicetrace.studies.settle import border_pairs, fit_border, summarise

    classify, settle = classify_on_slice("seed", config=cfg), settle_on_slice("seed", config=cfg)
    dists = np.logspace(-11, -4, ctx.pick(22, 8))
    fits = []
    for pa, pb in border_pairs(s, ctx.pick(BORDERS_FULL, 2), ctx.rng):
        f, _ = fit_border(classify, settle, np.array(pa), np.array(pb), dists)
        fits.append(f)
    ctx.n_throws += classify.n_evals + settle.n_evals
    out = summarise(fits)
    lam = np.asarray(out.pop("all"), dtype=float)
    out.pop("r")
    out["n_borders"] = len(fits)
    out["lambdas"] = lam
    if len(lam):
        out["mean"] = float(lam.mean())
        out["mean_stderr"] = float(lam.std(ddof=1) / math.sqrt(len(lam))) if len(lam) > 1 else None
    return out


def repetition_stats(s) -> dict:
    """The repetition measures of section c on one map: outcome autocorrelation and texture periods."""
    from dicetrace.analysis import find_periods, label_autocorrelation
    from dicetrace.studies.repetition import off_centre_max, periods_rows, stripe_spacing, texture_labels

    g, h = s.labels, s.spacing
    res = g.shape[0]
    tex = texture_labels(g, max(1.0, 0.015 * (res - 1)))
    rows_tex = periods_rows(find_periods(tex, spacing=h, min_strength=0.1), "", "texture")
    rows_out = periods_rows(find_periods(g, spacing=h, min_strength=0.3), "", "outcome")
    return {
        "outcome_offcentre_max_corr": off_centre_max(label_autocorrelation(g), int(0.05 * res)),
        "n_outcome_periods": len(rows_out),
        "outcome_periods": [{k: r[k] for k in ("dx", "dy", "length", "strength")} for r in rows_out],
        "texture_offcentre_max_corr": off_centre_max(label_autocorrelation(tex), int(0.05 * res)),
        "texture_periods": [{k: r[k] for k in ("dx", "dy", "length", "strength")} for r in rows_tex],
        "texture_stripe_spacing": stripe_spacing(rows_tex),
    }


def face_stats(g: np.ndarray, ref: np.ndarray | None) -> dict:
    """Face fractions with block errors (as section a), and a χ² test of the face counts against ``ref``'s."""
    from scipy.stats import chi2_contingency

    from dicetrace.analysis import basins_fractions_table
    from dicetrace.studies.cells import block_fraction_stderr

    fr = {str(int(r.label)): {"fraction": float(r.fraction), "count": int(r.count),
                         "block_stderr": block_fraction_stderr(g, int(r.label))}
          for r in basins_fractions_table(g).itertuples() if r.label > 0}
    out = {"fractions": fr}
    if ref is not None:
        counts = np.array([[int((x == k).sum()) for k in range(1, 7)] for x in (g, ref)])
        counts = counts[:, counts.sum(axis=0) > 0]
        chi2, p, dof, _ = chi2_contingency(counts)
        out.update(chi2_vs_discrete=float(chi2), chi2_dof=int(dof), chi2_p_vs_discrete=float(p))
    return out


def measure_map(ctx: Context, window: str, model: str, opts: dict, res: int, ref=None) -> tuple[dict, object]:
    """Every map measure of one window and model, and its certificate: (numbers, the sample)."""
    from dicetrace.analysis import agreement
    from dicetrace.analysis.simulator import classify_on_slice
    from dicetrace.analysis.transient import certify_map
    from dicetrace.studies.cells import cell_stats
    from dicetrace.studies.fractal import measures

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
        certificate=_agreement_dict(cert.tightened), floor=_agreement_dict(cert.floor),
        above_floor=cert.converged, converged=converged_verdict(cert),
        cells=cs, settle=settle_stats(s), repetition=repetition_stats(s), divergence=settle_divergence(ctx, s, cfg),
        **face_stats(g, None if ref is None else ref.labels),
    )
    if ref is not None:
        row["agreement_with_discrete"] = _agreement_dict(agreement(g, ref.labels))
    ctx.log(f"{window} {model}: certificate {cert.tightened.fraction:.3f} (floor {cert.floor.fraction:.3f}, "
            f"{verdict_text(row)}), {cs['n_cells']} cells, "
            f"α pert {row.get('alpha_pert', math.nan):.3f}, Sbb {row['Sbb']:.3f}")
    return row, s


def converged_verdict(cert) -> bool:
    """Converged: the certificate is not below the chaos floor (:func:`certify_map`'s rule) and its agreement
    beats chance (Cohen's κ more than 3 standard errors above 0; where the floor itself is at chance, a map at
    chance would otherwise pass)."""
    t = cert.tightened
    return bool(cert.converged and t.kappa - 3 * t.kappa_stderr > 0)


def _agreement_dict(a) -> dict:
    return {"fraction": a.fraction, "ci": list(a.ci), "chance": a.chance, "kappa": a.kappa,
            "kappa_stderr": a.kappa_stderr, "n": a.n}


def changes(rows: dict, a: str = "discrete", b: str = "converged", sigma: float = CHANGE_SIGMA) -> list[dict]:
    """The measures of one window that differ between models ``a`` and ``b`` by more than ``sigma`` standard errors.

    Each entry: measure, the two values, their difference in standard errors
    (``z``), and ``changed``. Only measures with an error bar are judged; the
    face counts by their χ² test (changed when p < 0.001).
    """
    ra, rb = rows[a], rows[b]
    out = []
    for key, label, get in MEASURES_WITH_ERRORS:
        va, ea = get(ra)
        vb, eb = get(rb)
        if va is None or vb is None or not (math.isfinite(va) and math.isfinite(vb)):
            continue
        if not (ea and eb and math.isfinite(ea) and math.isfinite(eb)):
            continue  # no error bar on one side: not judged
        z = abs(vb - va) / math.hypot(ea, eb)
        out.append({"key": key, "measure": label, a: va, b: vb, "z": z, "changed": bool(z > sigma)})
    p = rb.get("chi2_p_vs_discrete") if a == "discrete" else None
    if p is not None:
        out.append({"key": "faces", "measure": "face counts (χ² p)", a: None, b: p, "z": None,
                    "changed": bool(p < 1e-3)})
    return out


def _pair(key, *errs):
    """Getter of ``r[key]`` and the first of the error keys ``errs`` that is finite and > 0."""
    def get(r):
        v = r.get(key)
        es = [r.get(e) for e in errs]
        e = next((float(x) for x in es if x is not None and math.isfinite(x) and x > 0), None)
        return (None if v is None else float(v)), e
    return get


def _nested(section, key, err=None):
    def get(r):
        d = r.get(section) or {}
        v = d.get(key)
        return (None if v is None else float(v)), (None if err is None or d.get(err) is None else float(d[err]))
    return get


#: (key, label, getter -> (value, stderr)) of the measures judged by :func:`changes`.
MEASURES_WITH_ERRORS = (
    ("boundary_fraction", "boundary fraction", _pair("boundary_fraction", "boundary_fraction_block_stderr")),
    ("alpha_box", "α boxes", _pair("alpha", "alpha_block_stderr", "alpha_stderr")),
    ("alpha_pert", "α perturbation", _pair("alpha_pert", "alpha_pert_stderr")),
    ("dim_mask", "D boundary mask", _pair("dim_mask", "dim_mask_stderr")),
    ("Sb", "Sb", _pair("Sb", "Sb_stderr")),
    ("Sbb", "Sbb", _pair("Sbb", "Sbb_stderr")),
    ("settle_mean", "mean settle time (s)", _nested("settle", "mean", "mean_stderr")),
    ("kappa", "escape rate κ (1/s)", _nested("settle", "kappa", "kappa_stderr")),
    ("lambda", "settle-time divergence λ, all fits (1/s)", _nested("divergence", "mean", "mean_stderr")),
)

#: The same getters by key.
MEASURES = {k: get for k, _, get in MEASURES_WITH_ERRORS}


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


# ----------------------------------------------------------------------------------------------- render

MODEL_TITLES = {"discrete": "discrete (seed, dt = 1 ms)", "converged": "converged seed", "physical": "physical"}


def verdict_text(r: dict) -> str:
    if r["converged"]:
        return "yes"
    return "**NO** (below the floor)" if not r["above_floor"] else "**NO** (agreement at chance)"


def _cert_text(r: dict) -> str:
    c, f = r["certificate"], r["floor"]
    return (f"{c['fraction']:.3f} [{c['ci'][0]:.3f}, {c['ci'][1]:.3f}], κ {c['kappa']:.2f} / floor "
            f"{f['fraction']:.3f} [{f['ci'][0]:.3f}, {f['ci'][1]:.3f}]")


def _numerics(r: dict) -> str:
    """The integrator of a model's row and its tolerance (adaptive) or step (fixed)."""
    from dicetrace.integrators import INTEGRATORS

    if INTEGRATORS[r["integrator"]].adaptive:
        return f"{r['integrator']}, tol {tol_text(r)}"  # rows written before tol_growth: uniform
    return f"{r['integrator']}, dt {1000 * r['dt_s']:g} ms"


def _model_header(r: dict) -> str:
    return f"{r['model']} ({_numerics(r)})"


def window_table(rows: dict) -> str:
    """One window's measures, one column per model, and the discrete → converged change in standard errors."""
    ms = [rows[m] for m in MODEL_NAMES]
    z = {c["key"]: c for c in rows["changes"]}

    def line(label, vals, key=None):
        r = {"measure": label, **{m: v for m, v in zip(MODEL_NAMES, vals)}}
        c = z.get(key)
        if c is not None:
            r["z"] = (_p_text(c["converged"]) if c["z"] is None else f"{c['z']:.1f}") + (" **changed**" if c[
                "changed"] else "")
        return r

    def face(k):
        f = [r["fractions"].get(str(k), {}) for r in ms]  # keys are strings, as in the JSON
        return [pm(x.get("fraction"), x.get("block_stderr"), ".3f") for x in f]

    lines = [
        line("integrator", [_numerics(r) for r in ms]),
        line("certificate (10× tighter) / chaos floor", [_cert_text(r) for r in ms]),
        line("converged", [verdict_text(r) for r in ms]),
        line("agreement with the discrete map (κ)", ["–"] + [
            f"{r['agreement_with_discrete']['fraction']:.3f} (κ {r['agreement_with_discrete']['kappa']:.2f})"
            for r in ms[1:]]),
        line("cells", [str(r["cells"]["n_cells"]) for r in ms]),
        line("cells / 1000 nodes", [f"{r['cells']['cells_per_1000_nodes']:.1f}" for r in ms]),
        line("nodes in 1-node cells", [f"{r['cells']['frac_nodes_in_singletons']:.3f}" for r in ms]),
        line("largest cell (fraction, face)", [f"{r['cells']['largest_cell_frac']:.4f} ({r['cells']['largest_cell_label']})"
                                               for r in ms]),
        line("median cell (nodes)", [f"{r['cells']['median_size']:.0f}" for r in ms]),
        *[line(f"face {k} fraction", face(k)) for k in range(1, 7)],
        line("face counts vs discrete: χ² p", ["–"] + [_p_text(r.get("chi2_p_vs_discrete")) for r in ms[1:]], "faces"),
        line("boundary fraction", [pm(r["boundary_fraction"], r["boundary_fraction_block_stderr"]) for r in ms],
             "boundary_fraction"),
        line("α boxes", [pm(*MEASURES["alpha_box"](r)) for r in ms], "alpha_box"),
        line("α resolution", [fmt(r.get("alpha_res"), ".3f") for r in ms]),
        line("α perturbation", [pm(r.get("alpha_pert"), r.get("alpha_pert_stderr")) for r in ms], "alpha_pert"),
        line("D = 2 − α boxes", [f"{r['dimension']:.3f}" for r in ms]),
        line("D boundary mask", [pm(r["dim_mask"], r["dim_mask_stderr"]) for r in ms], "dim_mask"),
        line("Sb", [pm(r["Sb"], r["Sb_stderr"]) for r in ms], "Sb"),
        line("Sbb (> ln 2?)", [f"{pm(r['Sbb'], r['Sbb_stderr'])} ({'yes' if r['fractal_boundary'] else 'no'})"
                               for r in ms], "Sbb"),
        line("Wada merge", [("r=" + str(r["wada_merge_r"])) if r.get("wada_merge_r") is not None else
                            (f"no (far {r['wada_merge_far_r5']:.2f})" if "wada_merge_far_r5" in r else "–") for r in ms]),
        line("settle time mean (s)", [pm(r["settle"]["mean"], r["settle"]["mean_stderr"], ".4f") for r in ms],
             "settle_mean"),
        line("settle time median / 90 % / max (s)", [f"{r['settle']['median']:.2f} / {r['settle']['q90']:.2f} / "
                                                     f"{r['settle']['max']:.2f}" for r in ms]),
        line("settle time at borders / inside cells (s)", [f"{fmt(r['settle']['border_mean'], '.2f')} / "
                                                           f"{fmt(r['settle']['interior_mean'], '.2f')}" for r in ms]),
        line("unsettled throws", [str(r["settle"]["n_unsettled"]) for r in ms]),
        line("escape rate κ (1/s)", [pm(r["settle"].get("kappa"), r["settle"].get("kappa_stderr"), ".1f") for r in ms],
             "kappa"),
        line("settle-time divergence λ, all sides (1/s)", [
            f"{pm(r['divergence'].get('mean'), r['divergence'].get('mean_stderr'), '.1f')} "
            f"({r['divergence']['n_fits']} sides)" for r in ms], "lambda"),
        line("λ median ± bootstrap / clean fits (1/s)", [
            f"{pm(r['divergence'].get('median'), r['divergence'].get('median_stderr'), '.1f')} / "
            f"{pm(r['divergence'].get('clean_mean'), r['divergence'].get('clean_stderr'), '.1f')} "
            f"({r['divergence']['n_clean']})" for r in ms]),
        line("outcome autocorrelation, largest off-centre", [f"{r['repetition']['outcome_offcentre_max_corr']:.2f}"
                                                             for r in ms]),
        line("outcome period vectors (Δx, Δy; strength ≥ 0.3)", [", ".join(
            f"({p['dx']:.3g}, {p['dy']:.3g}; {p['strength']:.2f})" for p in r["repetition"].get("outcome_periods", [])[:2])
            or "none" for r in ms]),
        line("texture period vectors (Δx, Δy)", [", ".join(f"({p['dx']:.3g}, {p['dy']:.3g})" for p in
                                                           r["repetition"]["texture_periods"][:2]) or "none"
                                                 for r in ms]),
        line("texture stripe spacing", [fmt(r["repetition"]["texture_stripe_spacing"], ".3g") for r in ms]),
    ]
    cols = [("measure", "measure", "")] + [(m, _model_header(r), "") for m, r in zip(MODEL_NAMES, ms)] + [
        ("z", f"discrete → converged (σ; changed > {CHANGE_SIGMA:g} σ)", "")]
    return md_table(lines, cols)


def changes_text(by: dict) -> str:
    """A list, per window, of the measures that change from the discrete to the converged model."""
    lines = []
    for w in WINDOWS:
        ch = by[w]["changes"]
        yes = [c for c in ch if c["changed"]]
        no = [c for c in ch if not c["changed"]]
        conv = by[w]["converged"]
        tag = "" if conv["converged"] else " (the converged map is **not certified**: read with care)"
        desc = "; ".join(f"{c['measure']} {_fmt_change(c)}" for c in yes) or "nothing beyond the error bars"
        lines.append(f"- **{w}**{tag}: changed: {desc}. Unchanged within {CHANGE_SIGMA:g} σ: "
                     f"{', '.join(c['measure'] for c in no) or 'none'}.")
    return "\n".join(lines)


def _p_text(p) -> str:
    """A p-value; one that underflows to 0 as an upper bound."""
    if p is None:
        return "–"
    return "p < 1e-300" if p == 0 else f"p = {p:.1e}"


def _fmt_change(c: dict) -> str:
    if c["z"] is None:
        return f"({_p_text(c['converged'])})"
    return f"{c['discrete']:.3g} → {c['converged']:.3g} ({c['z']:.0f} σ)"


def answers(by: dict, summary: dict) -> dict[str, str]:
    """The "converged model" cells of the answers table (Markdown, no line breaks)."""
    c = {w: by[w]["converged"] for w in WINDOWS}
    rep = {w: c[w]["repetition"] for w in ("zoom-out", "more-out")}
    tex = rep["zoom-out"]["texture_periods"]
    s = summary["converged"]
    cert = f"{s['n_converged']} of {s['n_maps']} converged-seed maps certified"
    return {
        "periods": ("Largest off-centre autocorrelation of the outcomes "
                    f"{rep['zoom-out']['outcome_offcentre_max_corr']:.2f} (zoom-out), "
                    f"{rep['more-out']['outcome_offcentre_max_corr']:.2f} (more-out), "
                    f"{c['home']['repetition']['outcome_offcentre_max_corr']:.2f} (home); outcome period vectors "
                    "of strength ≥ 0.3: " + "; ".join(
                        f"{w} " + (", ".join(f"({p['dx']:.4g}, {p['dy']:.4g}), {p['length'] / c[w]['spacing']:.1f} "
                                             "grid nodes long" for p in c[w]["repetition"].get("outcome_periods", [])[:2])
                                   or "none") for w in ("home", "zoom-out", "more-out"))
                    + " (a lag of a few nodes is the size of the larger cells, not a repetition)"
                    + ". Texture periods in zoom-out: "
                    + (", ".join(f"({p['dx']:.4f}, {p['dy']:.4f})" for p in tex[:2]) or "none")
                    + f"; more-out texture stripe spacing {fmt(rep['more-out']['texture_stripe_spacing'], '.2f')}."),
        "alpha": (f"α (perturbation) from {fmt(s['alpha_pert_min'], '.2f')} to {fmt(s['alpha_pert_max'], '.2f')} "
                  f"over home, zoom-out, more-out, red sea (discrete, same grids: "
                  f"{fmt(summary['discrete']['alpha_pert_min'], '.2f')}–{fmt(summary['discrete']['alpha_pert_max'], '.2f')}); "
                  f"boundary-mask dimension {fmt(s['dim_mask_min'], '.2f')}–{fmt(s['dim_mask_max'], '.2f')}. "
                  f"Table in section l ({cert})."),
        "lambda": ("Settle-time divergence T ≈ T0 − ln(d)/λ at borders of the converged maps, all fitted sides "
                   "(no selection): " + "; ".join(
                       f"{w} {pm(c[w]['divergence'].get('mean'), c[w]['divergence'].get('mean_stderr'), '.1f')} /s "
                       f"(discrete {pm(by[w]['discrete']['divergence'].get('mean'), by[w]['discrete']['divergence'].get('mean_stderr'), '.1f')})"
                       for w in WINDOWS) + "."),
        "changes": (f"Certified (section l): {cert}, {summary['physical']['n_converged']} of "
                    f"{summary['physical']['n_maps']} physical maps, {summary['discrete']['n_converged']} of "
                    f"{summary['discrete']['n_maps']} discrete ones. Beyond {CHANGE_SIGMA:g} σ, converging changes: "
                    + "; ".join(f"{w}: {', '.join(summary['changed'][w]) or 'nothing'}" for w in WINDOWS) + "."),
    }


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt

    from dicetrace.analysis.plot import plot_outcome_map

    by, res = c.results["by"], c.results["res"]
    fig, axes = plt.subplots(len(WINDOWS), len(MODEL_NAMES), figsize=(4.2 * len(MODEL_NAMES), 3.9 * len(WINDOWS)))
    for i, w in enumerate(WINDOWS):
        for j, m in enumerate(MODEL_NAMES):
            ax, r, s = axes[i, j], by[w][m], c.plot[(w, m)]
            ok = r["converged"]
            title = (f"{w}, {MODEL_TITLES[m]}\ncertificate {r['certificate']['fraction']:.3f} vs floor "
                     f"{r['floor']['fraction']:.3f}: {'converged' if ok else 'NOT CONVERGED'}")
            plot_outcome_map(s.labels, extent=s.extent, ax=ax, legend=False, title=title)
            ax.title.set_fontsize(8)
            if not ok:
                ax.title.set_color("red")
                for sp in ax.spines.values():
                    sp.set_edgecolor("red")
                    sp.set_linewidth(3)
    fig.tight_layout()
    out.save_fig(fig, "l_maps", caption=f"The four windows ({res}² each) in the discrete model (left), the program's "
                 "force law integrated to convergence (middle) and the physical preset (right). Each title gives the "
                 "map's convergence certificate against its chaos floor; a map below its floor, or whose agreement with "
                 "the 10× tighter map is at chance, is framed in red and marked NOT CONVERGED.")

    fig, axes = plt.subplots(1, len(WINDOWS), figsize=(4.2 * len(WINDOWS), 3.8), sharey=True)
    for ax, w in zip(axes, WINDOWS):
        for k, m in enumerate(MODEL_NAMES):
            r = by[w][m]
            f = np.asarray(r["pert_f"], dtype=float)
            n = r["pert_n"]
            okf = f > 0
            eps = np.asarray(r["pert_eps_rel"])
            err = np.sqrt(np.maximum(f * (1 - f), 1e-12) / n)  # binomial stderr of each f(ε)
            ax.errorbar(eps[okf], f[okf], yerr=err[okf], fmt="o-", ms=3, capsize=2, color=f"C{k}",
                        label=f"{m} α={fmt(r.get('alpha_pert'), '.2f')}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ε / window width")
        ax.set_title(w)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("f(ε): pairs with different outcomes")
    fig.tight_layout()
    out.save_fig(fig, "l_uncertainty", caption="Fraction of uncertain random pairs f(ε) per window and model "
                 "(binomial 1-stderr bars); the slope is the uncertainty exponent α.")

    fig, ax = plt.subplots(figsize=(8, 3.8))
    x = np.arange(len(WINDOWS))
    for k, m in enumerate(MODEL_NAMES):
        for key, mk, dx in (("alpha_pert", "o", -0.2), ("alpha", "s", 0.05)):
            err = "alpha_pert_stderr" if key == "alpha_pert" else "alpha_block_stderr"
            ax.errorbar(x + dx + 0.06 * k, [by[w][m].get(key) or np.nan for w in WINDOWS],
                        yerr=[by[w][m].get(err) or 0 for w in WINDOWS], fmt=mk, color=f"C{k}", capsize=3,
                        mfc="none" if key == "alpha" else None,
                        label=f"{m}, {'perturbation' if key == 'alpha_pert' else 'boxes'}")
    ax.set_xticks(x, WINDOWS)
    ax.set_ylabel("uncertainty exponent α")
    ax.legend(fontsize=7, ncol=3)
    ax.set_title("α by perturbation (filled) and boxes (open), 1-stderr bars")
    fig.tight_layout()
    out.save_fig(fig, "l_alpha", caption="The uncertainty exponent per window and model.")

    for w in WINDOWS:
        out.tables[f"window_{w}"] = window_table(by[w])
    out.tables["changes"] = changes_text(by)
    out.tables.update({f"answer_{k}": v for k, v in answers(by, c.results["summary"]).items()})
    out.tables["certificates"] = md_table([{
        "w": w, "m": m, "integ": _numerics(by[w][m]), "cert": _cert_text(by[w][m]),
        "conv": verdict_text(by[w][m])} for w in WINDOWS for m in MODEL_NAMES], [
        ("w", "window", ""), ("m", "model", ""), ("integ", "integrator", ""),
        ("cert", "certificate [95 % CI], Cohen's κ / chaos floor [95 % CI]", ""), ("conv", "converged", "")])


def rerender(out, options: Options = Options()) -> Path:
    """Redraw the figures and tables of a finished run in ``out`` without simulating.

    Reads ``out/results/converged.json`` and the grids cached in
    ``out/cache`` (``options`` must be those of the run, for the cache keys),
    recomputes the summary, the changes and the tables from the stored
    numbers (and the repetition measures, a deterministic function of the
    cached grids), and rewrites the JSON. RuntimeError if a grid is not cached.
    """
    import json

    from dicetrace.studies.context import write_json

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
