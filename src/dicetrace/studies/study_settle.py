"""Study g (settle): settle time at cell borders (writeup 4.1–4.2 and 5.6).

A settle-time map ("2-D scatter with time axis"), then borders located by
bisection to 1e-12 (slice units) along short segments that cross them, the
settle time sampled at distances 1e-11 … 1e-4 on both sides, and the law
T ≈ T0 − ln(d)/λ fitted on each side. λ is compared with the instability
rate of a uniform cube balanced on an edge with its pivot held,
edge_balance_rate() = √(3g / (2√2 s)) ≈ 22.8 /s (s = 2 cm), and with the
rate of the same cube on a frictionless floor (pivot free to slide),
√(6g / (√2 s)) ≈ 45.6 /s. Controls: the same model integrated accurately
(contact-substep RK4 instead of the program's semi-implicit Euler at 1 ms),
and the ``physical`` preset (Coulomb friction per node), also with
contact-substep.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.analysis import edge_balance_rate
from dicetrace.analysis.plot import plot_settle_map
from dicetrace.analysis.settle import border_pairs, divergence_summary, fit_border, free_pivot_rate
from dicetrace.analysis.simulator import classify_on_slice, settle_on_slice
from dicetrace.studies.context import Computed, Context, Output
from dicetrace.studies.text import compared, md_table, pm

NAME = "settle"
#: (key, preset, integrator, borders in the full run, in the quick run, description)
RUNS = (
    ("seed", "seed", None, 40, 3, "the program: seed preset, semi-implicit Euler, dt = 1 ms"),
    ("seed-substep", "seed", "contact-substep", 30, 2, "the same model integrated accurately (contact-substep RK4)"),
    ("physical-substep", "physical", "contact-substep", 30, 2,
     "the physical preset (per-node Coulomb friction), contact-substep RK4"),
)
#: Two interquartile ranges closer than this fraction of the larger are called "about as broad".
SPREAD_TIE = 0.1
#: Window whose borders are located, and the maps drawn.
BORDER_WINDOW = "red-sea-2"
MAP_WINDOWS = ("red-sea", "home")


def borders(ctx: Context, preset: str, integrator, n_borders: int, res):
    """Random face-neighbour pairs of a grid of the border window whose outcomes differ (both settled)."""
    kw = {}
    if preset != "seed":
        kw["preset"] = preset
    if integrator is not None:
        kw["integrator"] = integrator
    return border_pairs(ctx.sample(BORDER_WINDOW, res, **kw), n_borders, ctx.rng)


def compute(ctx: Context) -> Computed:
    results: dict = {"predicted": {"fixed_pivot_per_s": edge_balance_rate(), "free_pivot_per_s": free_pivot_rate()}}
    res = ctx.res(401, 41)
    maps = {}
    for w in MAP_WINDOWS:
        s = maps[w] = ctx.sample(w, res)
        results[f"map_{w}"] = {"res": res, "mean_settle_s": float(s.t_settle_s.mean()),
                               "max_settle_s": float(s.t_settle_s.max()),
                               "p99_settle_s": float(np.quantile(s.t_settle_s, 0.99))}
    dists = np.logspace(-11, -4, ctx.pick(22, 8))
    results["distances"] = dists
    runs, profiles = {}, {}
    for key, preset, integ, nf, nq, desc in RUNS:
        kw = {"integrator": integ} if integ else {}
        classify = classify_on_slice("seed", preset=preset, **kw)
        settle = settle_on_slice("seed", preset=preset, **kw)
        pairs = borders(ctx, preset, integ, ctx.pick(nf, nq), ctx.pick(101, 21))
        fits, profiles[key] = [], []
        for pa, pb in pairs:
            f, prof = fit_border(classify, settle, np.array(pa), np.array(pb), dists)
            fits.append(f)
            profiles[key].append(prof)
        summ = divergence_summary(fits)
        runs[key] = {"fits": fits, "summary": summ, "description": desc}
        ctx.log(f"{key}: λ median {summ.get('median', float('nan')):.2f} /s over {summ['n_fits']} fits, "
                f"clean mean {summ.get('clean_mean', float('nan')):.2f} ({summ['n_clean']})")
    results["runs"] = runs
    results["res"] = res
    return Computed(results, {"maps": maps, "profiles": profiles})


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    R = c.results
    for w, s in c.plot["maps"].items():
        fig = plot_settle_map(s.labels, s.t_settle_s, extent=s.extent,
                              title=f"{w}: outcome shaded by settle time ({R['res']}²)")
        out.save_fig(fig, f"g_settle_map_{w}", caption=f"Settle-time map of the {w} window: darker = slower; "
                     "cell borders show as dark seams where the die balances on an edge.")
    lam_fixed, lam_free = R["predicted"]["fixed_pivot_per_s"], R["predicted"]["free_pivot_per_s"]
    fig, axes = plt.subplots(1, 2, figsize=(11.5, 4.3))
    shown = 0
    for f, prof in zip(R["runs"]["seed"]["fits"], c.plot["profiles"]["seed"]):
        if shown >= 4 or not (f.get("lo") and f.get("hi")):
            continue
        for side, mk in (("lo", "o"), ("hi", "s")):
            p = prof[prof.side == side]
            line = axes[0].semilogx(p.d, p.t_settle_s, mk, ms=3, color=f"C{shown}")[0]
            fit = f[side]
            axes[0].semilogx(p.d, fit["t0"] - np.log(p.d) / fit["lambda"], "-", color=line.get_color(), lw=0.8)
        axes[0].plot([], [], "-", color=f"C{shown}", label=f"{f['label_lo']}|{f['label_hi']}: λ = "
                     f"{f['lo']['lambda']:.1f}, {f['hi']['lambda']:.1f} /s")
        shown += 1
    axes[0].set_xlabel("distance d from the border (slice units)")
    axes[0].set_ylabel("settle time T / s")
    axes[0].set_title("T against d on both sides (○ one side, □ other), with fits")
    axes[0].legend(fontsize=7)
    bins = np.linspace(10, 60, 26)
    for (key, *_), col in zip(RUNS, ("C0", "C1", "C2")):
        lam = R["runs"][key]["summary"]["all"]
        axes[1].hist(np.clip(lam, bins[0], bins[-1]), bins=bins, alpha=0.5, color=col, label=key)
    axes[1].axvline(lam_fixed, color="k", ls="--", label=f"held pivot {lam_fixed:.1f} /s")
    axes[1].axvline(lam_free, color="k", ls=":", label=f"sliding pivot {lam_free:.1f} /s")
    axes[1].set_xlabel("fitted λ / (1/s)")
    axes[1].set_ylabel("border sides")
    axes[1].set_title("Fitted divergence rates")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    out.save_fig(fig, "g_settle_divergence", caption="Left: settle time against the distance from four located "
                 "borders, both sides, with T = T0 − ln(d)/λ fits. Right: λ of every side fitted (clipped to "
                 "10–60 /s) for the three runs, against the two predictions.")
    rows = []
    for key, *_ in RUNS:
        sm = R["runs"][key]["summary"]
        rows.append({"preset": key, "desc": R["runs"][key]["description"], "n": sm["n_fits"],
                     "med": pm(sm.get("median", math.nan), sm.get("median_stderr"), ".1f"),
                     "iqr": f"{sm.get('q25', math.nan):.1f}–{sm.get('q75', math.nan):.1f}",
                     "nc": sm["n_clean"], "cm": pm(sm.get("clean_mean", math.nan), sm.get("clean_stderr"), ".1f")})
    out.tables["lambda"] = md_table(rows, [
        ("preset", "run", ""), ("desc", "model and integrator", ""), ("n", "sides fitted", "d"),
        ("med", "median λ (1/s) ± bootstrap se", ""), ("iqr", "interquartile range", ""),
        ("nc", "clean fits (r < −0.995)", "d"), ("cm", "mean λ of clean fits ± se", "")])


def rate_comparison(other: dict, base: dict, subject: str, base_name: str) -> str:
    """A sentence comparing two runs' fitted rates from their summaries (``median``, ``median_stderr``, ``q25``,
    ``q75``, ``n_clean``, ``n_fits``): higher or lower where the medians differ by more than two standard errors
    of the difference, the spread by the interquartile ranges, the clean fits by their share of the sides."""
    med, med0 = other["median"], base["median"]
    err = math.hypot(other.get("median_stderr") or 0.0, base.get("median_stderr") or 0.0)
    rate = compared(med, med0, ("a higher rate than", "a lower rate than", "a rate not told apart from that of"),
                    err=err)
    iqr, iqr0 = other["q75"] - other["q25"], base["q75"] - base["q25"]
    spread = compared(iqr, iqr0, ("a broader spread", "a narrower spread", "a spread about as broad"), rel=SPREAD_TIE)
    share, share0 = other["n_clean"] / max(other["n_fits"], 1), base["n_clean"] / max(base["n_fits"], 1)
    clean = compared(share, share0, ("more", "fewer", "as many"))
    return (f"{subject} gives {rate} {base_name} (median {pm(med, other.get('median_stderr'), '.1f')} against "
            f"{pm(med0, base.get('median_stderr'), '.1f')} /s), {spread} (interquartile range {iqr:.1f} against "
            f"{iqr0:.1f} /s) and {clean} clean fits ({other['n_clean']} of {other['n_fits']} sides against "
            f"{base['n_clean']} of {base['n_fits']})")


def physical_vs_seed(results: dict) -> str:
    """The report's comparison of the ``physical`` run with the discrete model, from this study's results."""
    runs = results["runs"]
    return rate_comparison(runs["physical-substep"]["summary"], runs["seed"]["summary"],
                           "The `physical` preset (Coulomb friction per node)", "the discrete model")


#: The sentences of the report that this study writes from its numbers when the report is assembled
#: (``{{s:settle.NAME}}`` in the template).
SENTENCES = {"physical_vs_seed": physical_vs_seed}
