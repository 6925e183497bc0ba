"""Study e (damping): damping and chaos (writeup 5.2).

The home window at γ = 0.005 s/cm (the writeup's) and 0.01 s/cm (its
comparison), plus 0.0025 and 0.02, in the program's discrete model and,
on a smaller grid, with its force law integrated to convergence
(``CONVERGED``): outcome maps and the chaos measures of
``chaos_sweep`` with error bars — boundary fraction, uncertainty exponent
(box counting on the grid, and random-pair perturbation with the
simulator), basin entropies — and the mean settle time and number of
contacts, the writeup's suggested cause.
"""

from __future__ import annotations

import numpy as np

from dicetrace.analysis import boundary_fraction, chaos_sweep
from dicetrace.analysis.plot import plot_outcome_map
from dicetrace.analysis.simulator import classify_on_slice, run_on_slice, sample_window
from dicetrace.params import make_config
from dicetrace.status import LABELS, Status
from dicetrace.studies.context import Computed, Context, Output, window_ranges
from dicetrace.studies.text import md_table, pm

NAME = "damping"
GAMMAS = (0.0025, 0.005, 0.01, 0.02)
#: The program's dt and half of it (the time-step check), s.
DT_CHECK = (0.001, 0.0005)
#: The program's force law integrated to convergence: the same sweep on the converged die
#: (DOP853 at this tolerance agrees with tol 1e-11 on every one of the accuracy study's 300
#: zoom-out throws of the seed preset; study l certifies the seed law's maps at this accuracy).
CONVERGED = {"integrator": "contact-dop853", "tol": 1e-7}


def _contact_counts(ctx: Context, extra: dict) -> None:
    """Mean contact changes and airborne phases per throw, from a random sample of the window."""
    m = ctx.pick(4000, 200)
    pts = ctx.rng.random((m, 2)) * 0.1
    for gam in GAMMAS:
        r = run_on_slice(pts, "seed", gamma=gam, sequences=True)
        nchg = np.array([len(q.split("-")) - 1 for q in r.sequences])
        nb = np.array([q.count("-0-") + q.endswith("-0") for q in r.sequences])
        extra[gam]["mean_contact_changes"] = float(nchg.mean())
        extra[gam]["mean_contact_changes_stderr"] = float(nchg.std(ddof=1) / np.sqrt(m))
        extra[gam]["mean_airborne_phases"] = float(nb.mean())
        extra[gam]["mean_airborne_phases_stderr"] = float(nb.std(ddof=1) / np.sqrt(m))


def _dt_check(ctx: Context) -> list[dict]:
    """The same window at the program's dt and half of it, on a smaller grid."""
    rdt = ctx.pick(101, 21)
    rows = []
    for gam in GAMMAS:
        for dt in DT_CHECK:
            sd = sample_window("home", rdt, config=make_config("seed", gamma=gam, dt_s=dt))
            ctx.n_throws += sd.labels.size
            _, cnt = np.unique(sd.labels, return_counts=True)
            rows.append({"gamma": gam, "dt_s": dt, "res": rdt, "bf": boundary_fraction(sd.labels),
                         "blow_ups": int((sd.status_code == Status.BLOW_UP).sum()),
                         "mean_settle_s": float(sd.t_settle_s.mean()),
                         "largest_outcome_frac": float(cnt.max() / cnt.sum())})
    return rows


def _chaos_rows(ctx: Context, grids, classifiers, extra, npts: int, eps, res: int):
    """``chaos_sweep`` over the γ grids at ``npts`` random points of the window; (table, rows with ``extra``)."""
    pts = ctx.rng.random((npts, 2)) * 0.1
    table = chaos_sweep(grids, classifiers=classifiers, points=pts, eps_list=eps, rng=ctx.rng,
                        param_name="gamma", spacing=0.1 / (res - 1), n_blocks=4, n_boot=200)
    return table, [{**rec, **extra[rec["gamma"]]} for rec in table.to_dict("records")]


def compute(ctx: Context) -> Computed:
    res = ctx.res(401, 41)
    grids, classifiers, extra = {}, {}, {}
    for gam in GAMMAS:
        s = ctx.sample("home", res, gamma=gam)
        grids[gam] = s.labels
        classifiers[gam] = classify_on_slice("seed", gamma=gam)
        sub = [s.labels[::k, ::k] for k in (1, 2, 4) if (res - 1) % k == 0]
        extra[gam] = {
            "mean_settle_s": float(s.t_settle_s.mean()),
            "median_settle_s": float(np.median(s.t_settle_s)),
            "p99_settle_s": float(np.quantile(s.t_settle_s, 0.99)),
            "n_unsettled": int((s.labels == -1).sum()),
            "status_counts": np.bincount(s.status_code.ravel(), minlength=len(LABELS)).tolist(),
            "n_undefined": int((s.labels == 0).sum()),
            "boundary_fraction_by_res": [{"res": g.shape[0], "bf": boundary_fraction(g)} for g in sub],
        }
        ctx.log(f"γ={gam}: mean settle {extra[gam]['mean_settle_s']:.3f} s")
    _contact_counts(ctx, extra)
    dt_rows = _dt_check(ctx)
    npts = ctx.pick(3000, 150)
    eps = 0.1 * (np.logspace(-7, -2, 6) if not ctx.quick else np.logspace(-4, -1, 4))
    table, rows = _chaos_rows(ctx, grids, classifiers, extra, npts, eps, res)
    results = {"dt_check": dt_rows, "sweep": rows, "perturbation": {"npts": npts, "eps": eps}, "res": res,
               "converged": _converged_sweep(ctx, eps)}
    return Computed(results, {"grids": grids, "sweep_table": table})


def _converged_sweep(ctx: Context, eps) -> dict:
    """The sweep again with the force law integrated to convergence (``CONVERGED``), on a smaller grid."""
    res = ctx.res(201, 41)
    grids, classifiers, extra = {}, {}, {}
    for gam in GAMMAS:
        s = ctx.sample("home", res, gamma=gam, **CONVERGED)
        grids[gam] = s.labels
        classifiers[gam] = classify_on_slice("seed", gamma=gam, **CONVERGED)
        extra[gam] = {"mean_settle_s": float(s.t_settle_s[s.labels >= 0].mean()),
                      "n_unsettled": int((s.labels == -1).sum())}
        ctx.log(f"converged γ={gam}: mean settle {extra[gam]['mean_settle_s']:.3f} s")
    npts = ctx.pick(1000, 150)
    _, rows = _chaos_rows(ctx, grids, classifiers, extra, npts, eps, res)
    bf = [r["boundary_fraction"] for r in rows]
    be = [r.get("boundary_fraction_block_stderr", np.nan) for r in rows]
    trend = ("falls monotonically" if all(a > b for a, b in zip(bf, bf[1:])) else "does not fall monotonically")
    answer = (f"{'Yes' if bf[-1] < bf[0] else 'No'}, with {CONVERGED['integrator']} at tol {CONVERGED['tol']:g} too "
              f"(statistics only: these {res}² maps have no certificate): from γ = "
              f"{' → '.join(str(g) for g in GAMMAS)} s/cm the border fraction {trend}, "
              f"{' → '.join(f'{v:.3f} ± {e:.3f}' for v, e in zip(bf, be))}; γ = 0.02 is stable here.")
    return {"sweep": rows, "res": res, "npts": npts, **CONVERGED, "answer": answer}


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    R, grids = c.results, c.plot["grids"]
    res, rows = R["res"], R["sweep"]
    out.tables["dt_check"] = md_table(R["dt_check"], [
        ("gamma", "γ (s/cm)", ""), ("dt_s", "dt (s)", ""), ("res", "grid", "d"), ("bf", "boundary fraction", ".3f"),
        ("largest_outcome_frac", "most common outcome (fraction)", ".3f"), ("blow_ups", "blow-ups", "d"),
        ("mean_settle_s", "mean settle (s)", ".3f")])
    out.write_csv(c.plot["sweep_table"], "damping_sweep")

    fig, axes = plt.subplots(1, len(GAMMAS), figsize=(3.4 * len(GAMMAS) + 1, 3.6))
    for ax, gam in zip(axes, GAMMAS):
        plot_outcome_map(grids[gam], extent=list(window_ranges("home")), ax=ax, legend=False, title=f"γ = {gam} s/cm")
    fig.tight_layout()
    out.save_fig(fig, "e_maps", caption=f"The home window at four damping coefficients ({res}² each).")

    g = np.array(GAMMAS)
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.6))

    def series(ax, key, err, ylabel):
        y = np.array([r[key] for r in rows], dtype=float)
        e = np.array([r.get(err, np.nan) if err else np.nan for r in rows], dtype=float)
        ax.errorbar(g, y, yerr=np.where(np.isfinite(e), e, 0), fmt="o-", capsize=3)
        ax.set_xscale("log")
        ax.minorticks_off()
        ax.set_xticks(g, [str(v) for v in g])
        ax.set_xlabel("γ / (s/cm)")
        ax.set_ylabel(ylabel)

    series(axes[0, 0], "boundary_fraction", "boundary_fraction_block_stderr", "boundary fraction")
    series(axes[0, 1], "alpha", "alpha_block_stderr", "α (box counting)")
    series(axes[0, 2], "alpha_perturbation", "alpha_perturbation_stderr", "α (perturbation)")
    series(axes[1, 0], "Sb", "Sb_stderr", "basin entropy Sb")
    series(axes[1, 1], "Sbb", "Sbb_stderr", "boundary basin entropy Sbb")
    axes[1, 1].axhline(np.log(2), color="0.5", ls=":", label="ln 2")
    axes[1, 1].legend(fontsize=8)
    series(axes[1, 2], "mean_contact_changes", "mean_contact_changes_stderr", "mean contact changes per throw")
    ax2 = axes[1, 2].twinx()
    ax2.plot(g, [r["mean_settle_s"] for r in rows], "s--", color="C3")
    ax2.set_ylabel("mean settle time / s", color="C3")
    fig.suptitle(f"Chaos measures of the home window against damping ({res}² grids; error bars: 1 stderr)")
    fig.tight_layout()
    out.save_fig(fig, "e_measures", caption="Chaos measures against γ, with one-standard-error bars "
                 "(block errors over 4×4 sub-grids for the boundary fraction and α box; regression errors for α "
                 "perturbation; bootstrap for Sb, Sbb; sample errors for the contact count).")
    trows = [{
        "gamma": r["gamma"],
        "bf": pm(r["boundary_fraction"], r["boundary_fraction_block_stderr"], ".3f"),
        "a": pm(r["alpha"], r["alpha_block_stderr"], ".3f"),
        "ap": pm(r.get("alpha_perturbation", np.nan), r.get("alpha_perturbation_stderr"), ".3f"),
        "Sb": pm(r["Sb"], r["Sb_stderr"], ".3f"), "Sbb": pm(r["Sbb"], r["Sbb_stderr"], ".3f"),
        "t": r["mean_settle_s"], "nc": pm(r["mean_contact_changes"], r["mean_contact_changes_stderr"], ".1f"),
        "bf_res": " / ".join(f"{b['bf']:.3f}" for b in r["boundary_fraction_by_res"]),
        "uns": r["n_unsettled"], "blow": r["status_counts"][Status.BLOW_UP],
    } for r in rows]
    out.tables["sweep"] = md_table(trows, [
        ("gamma", "γ (s/cm)", ""), ("bf", "boundary fraction", ""), ("bf_res", "bf at res/1, /2, /4", ""),
        ("a", "α box", ""), ("ap", "α perturbation", ""), ("Sb", "Sb", ""), ("Sbb", "Sbb", ""),
        ("t", "mean settle (s)", ".3f"), ("nc", "contact changes", ""), ("uns", "not settled", "d"),
        ("blow", "of which blow-ups", "d")])
    conv = R["converged"]
    out.tables["converged_answer"] = conv["answer"]
    out.tables["sweep_converged"] = md_table([{
        "gamma": r["gamma"],
        "bf": pm(r["boundary_fraction"], r["boundary_fraction_block_stderr"], ".3f"),
        "a": pm(r["alpha"], r["alpha_block_stderr"], ".3f"),
        "ap": pm(r.get("alpha_perturbation", np.nan), r.get("alpha_perturbation_stderr"), ".3f"),
        "Sb": pm(r["Sb"], r["Sb_stderr"], ".3f"), "Sbb": pm(r["Sbb"], r["Sbb_stderr"], ".3f"),
        "t": r["mean_settle_s"], "uns": r["n_unsettled"],
    } for r in conv["sweep"]], [
        ("gamma", "γ (s/cm)", ""), ("bf", "boundary fraction", ""), ("a", "α box", ""), ("ap", "α perturbation", ""),
        ("Sb", "Sb", ""), ("Sbb", "Sbb", ""), ("t", "mean settle (s)", ".3f"), ("uns", "not settled", "d")])
