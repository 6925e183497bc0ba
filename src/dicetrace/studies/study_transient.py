"""Study j (transient): transient chaos of the discrete and the converged die: λ, κ and α, with convergence certificates.

For the home and red-sea windows and three models — the program's discrete
step (``seed``, dt = 1 ms), the program's force law integrated to
convergence (``seed`` with ``contact-adaptive`` at tol 1e-7) and the
``physical`` preset at its defaults — this study measures:

* the convergence certificate of each map (:func:`~dicetrace.analysis.transient.certify_map`:
  agreement with a 10× tighter integration against the chaos floor at a
  tenth of the grid spacing, with Wilson intervals and Cohen's κ);
* the finite-time Lyapunov exponent λ of the bouncing phase over a grid of
  the window (:func:`~dicetrace.analysis.transient.ftle_on_slice`): mean,
  spread, and the FTLE map beside the outcome map;
* the escape rate κ of the settle times, ``P(T > t) ~ exp(-κ t)`` past the
  median (:func:`~dicetrace.analysis.escape.escape_rate`);
* the uncertainty exponent α by random perturbation and by boxes;
* the relation of transient chaos for one unstable direction,
  ``α = κ / λ`` (Kantz & Grassberger 1985; Hsu, Ott & Grebogi 1988: the
  uncertain fraction scales with the codimension of the saddle's stable
  manifold, ``1 - d_s = κ/λ``, which a 2-D slice transverse to it inherits),
  both sides with error bars.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.analysis import escape_rate, survival_function, uncertainty_exponent, uncertainty_exponent_perturbation
from dicetrace.analysis.plot import plot_outcome_map
from dicetrace.analysis.simulator import classify_on_slice, sample_window
from dicetrace.analysis.transient import certify_map, ftle_on_slice
from dicetrace.params import make_config
from dicetrace.studies.context import Computed, Context, Output, window_ranges
from dicetrace.studies.text import md_table, pm, verdict_word

NAME = "transient"
WINDOWS = ("home", "red-sea")
#: model name -> make_config options
MODELS = {
    "discrete": {"preset": "seed"},
    "converged": {"preset": "seed", "integrator": "contact-adaptive", "tol": 1e-7},
    "physical": {"preset": "physical"},
}


def _config(model: str):
    opts = dict(MODELS[model])
    return make_config(opts.pop("preset"), **opts)


def _measure(ctx: Context, window: str, model: str) -> tuple[dict, dict]:
    cfg = _config(model)
    res = ctx.res(201, 11)
    s = sample_window(window, res, config=cfg)
    ctx.n_throws += s.labels.size
    t_max = cfg.numerics.t_max_s
    settled = s.labels >= 0
    kappa = escape_rate(s.t_settle_s[settled], min_tail=ctx.pick(50, 10), censored_at=t_max)
    ue_box = uncertainty_exponent(s.labels)
    (x0, x1), (y0, y1) = window_ranges(window)
    npts = ctx.pick(1500, 40)
    pts = np.column_stack([ctx.rng.uniform(x0, x1, npts), ctx.rng.uniform(y0, y1, npts)])
    width = min(x1 - x0, y1 - y0)
    eps = width * (np.logspace(-6, -2, 5) if not ctx.quick else np.logspace(-3, -1, 3))
    ue_pert = uncertainty_exponent_perturbation(classify_on_slice("seed", config=cfg), pts, eps, ctx.rng)
    ctx.n_throws += npts * (len(eps) + 1)
    ftle = ftle_on_slice(window, ctx.pick(32, 5), config=cfg)
    ctx.n_throws += 2 * ftle.ftle.size
    lam = ftle.ftle[np.isfinite(ftle.ftle)]
    lam_mean = float(lam.mean())
    lam_se = float(lam.std(ddof=1) / math.sqrt(len(lam))) if len(lam) > 1 else math.nan
    cert = certify_map(window, ctx.pick(61, 9), config=cfg)
    ctx.n_throws += 3 * cert.labels.size
    ratio = kappa.kappa / lam_mean
    ratio_se = ratio * math.hypot(kappa.stderr / kappa.kappa, lam_se / lam_mean)
    row = {
        "window": window, "model": model, "res": res, "integrator": cfg.numerics.integrator,
        "certificate": cert.tightened.fraction, "certificate_ci": list(cert.tightened.ci),
        "certificate_kappa": cert.tightened.kappa, "floor": cert.floor.fraction, "floor_ci": list(cert.floor.ci),
        "converged": cert.converged,
        "lambda_mean": lam_mean, "lambda_stderr": lam_se, "lambda_median": float(np.median(lam)),
        "lambda_iqr": [float(np.quantile(lam, 0.25)), float(np.quantile(lam, 0.75))],
        "kappa": kappa.kappa, "kappa_stderr": kappa.stderr, "kappa_t0": kappa.t0, "kappa_t1": kappa.t1,
        "kappa_n_tail": kappa.n_tail, "unsettled": int((~settled).sum()), "t_max_s": t_max,
        "alpha_perturbation": ue_pert.alpha, "alpha_perturbation_stderr": ue_pert.alpha_stderr,
        "alpha_box": ue_box.alpha, "alpha_box_stderr": ue_box.alpha_stderr,
        "kappa_over_lambda": ratio, "kappa_over_lambda_stderr": ratio_se,
    }
    ctx.log(f"{window} {model}: λ {lam_mean:.1f} ± {lam_se:.1f} /s, κ {kappa.kappa:.1f} /s, "
            f"α {ue_pert.alpha:.2f}, κ/λ {ratio:.2f}, certificate {cert.tightened.fraction:.3f} "
            f"(floor {cert.floor.fraction:.3f})")
    return row, {"labels": s.labels, "t": s.t_settle_s[settled], "ftle": ftle, "kappa": kappa}


def compute(ctx: Context) -> Computed:
    rows, plot = [], {}
    for window in WINDOWS:
        for model in MODELS:
            row, p = _measure(ctx, window, model)
            rows.append(row)
            plot[(window, model)] = p
    by: dict = {}
    for r in rows:
        by.setdefault(r["window"], {})[r["model"]] = r
    return Computed({"rows": rows, "by": by}, plot)


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    rows = c.results["rows"]
    fig, axes = plt.subplots(1, len(WINDOWS), figsize=(6 * len(WINDOWS), 4))
    for ax, window in zip(np.atleast_1d(axes), WINDOWS):
        for k, model in enumerate(MODELS):
            p = c.plot[(window, model)]
            t, s = survival_function(p["t"])
            ax.semilogy(t, np.maximum(s, 1e-6), color=f"C{k}", label=model)
            e = p["kappa"]
            tt = np.linspace(e.t0, e.t1, 20)
            s0 = float(np.mean(p["t"] > e.t0))
            ax.semilogy(tt, s0 * np.exp(-e.kappa * (tt - e.t0)), "--", color=f"C{k}", lw=1)
        ax.set_xlabel("settle time t / s")
        ax.set_ylabel("P(T > t)")
        ax.set_title(f"{window}: survival of settle times, fits dashed")
        ax.legend(fontsize=8)
    fig.tight_layout()
    out.save_fig(fig, "j_survival", caption="Survival of the settle times in each window and model, and the "
                 "exponential fit past the median (maximum likelihood).")

    fig, axes = plt.subplots(2, len(MODELS), figsize=(4 * len(MODELS), 7))
    for k, model in enumerate(MODELS):
        f = c.plot[("red-sea", model)]["ftle"]
        hx, hy = (f.x[1] - f.x[0]) / 2, (f.y[1] - f.y[0]) / 2  # pixels centred on the nodes, as the outcome map
        ext = [f.x[0] - hx, f.x[-1] + hx, f.y[0] - hy, f.y[-1] + hy]
        im = axes[0, k].imshow(f.ftle.T, origin="lower", extent=ext, aspect="auto", cmap="magma")
        fig.colorbar(im, ax=axes[0, k], label="FTLE / (1/s)")
        axes[0, k].set_title(f"red sea, {model}: FTLE")
        plot_outcome_map(f.outcome, extent=[(f.x[0], f.x[-1]), (f.y[0], f.y[-1])], ax=axes[1, k], legend=False,
                         title="outcome (same grid)")
    fig.tight_layout()
    out.save_fig(fig, "j_ftle", caption="The finite-time Lyapunov field of the bouncing phase over the red-sea "
                 "window (top) beside the outcomes on the same grid (bottom): ridges along the cell borders.")

    fig, ax = plt.subplots(figsize=(7, 4))
    labels = [f"{r['window']}\n{r['model']}" for r in rows]
    x = np.arange(len(rows))
    ax.errorbar(x - 0.1, [r["alpha_perturbation"] for r in rows], yerr=[r["alpha_perturbation_stderr"] for r in rows],
                fmt="o", capsize=3, label="α (perturbation)")
    ax.errorbar(x + 0.1, [r["kappa_over_lambda"] for r in rows], yerr=[r["kappa_over_lambda_stderr"] for r in rows],
                fmt="s", capsize=3, label="κ / λ")
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("exponent")
    ax.legend()
    ax.set_title("The transient-chaos relation α = κ/λ, both sides with 1-stderr bars")
    fig.tight_layout()
    out.save_fig(fig, "j_relation", caption="Uncertainty exponent α against κ/λ per window and model.")

    out.tables["transient"] = md_table([{
        "w": r["window"], "m": r["model"],
        "cert": f"{r['certificate']:.3f} (κ {r['certificate_kappa']:.2f})", "floor": f"{r['floor']:.3f}",
        "conv": {"converged": "yes", "statistics only": "statistics only"}.get(
            verdict_word(r["converged"], r["certificate"]), "**no**"),
        "lam": pm(r["lambda_mean"], r["lambda_stderr"], ".1f"), "kap": pm(r["kappa"], r["kappa_stderr"], ".1f"),
        "a": pm(r["alpha_perturbation"], r["alpha_perturbation_stderr"], ".2f"),
        "ab": pm(r["alpha_box"], r["alpha_box_stderr"], ".2f"),
        "kl": pm(r["kappa_over_lambda"], r["kappa_over_lambda_stderr"], ".2f"),
    } for r in rows], [
        ("w", "window", ""), ("m", "model", ""), ("cert", "certificate (agreement, Cohen's κ)", ""),
        ("floor", "chaos floor", ""), ("conv", "converged", ""), ("lam", "λ (1/s)", ""), ("kap", "κ (1/s)", ""),
        ("a", "α perturbation", ""), ("ab", "α boxes", ""), ("kl", "κ/λ", "")])
