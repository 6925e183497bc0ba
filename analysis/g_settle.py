"""Study g: settle time at cell borders (writeup 4.1–4.2 and 5.6).

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

    python analysis/g_settle.py [--quick] [--res N] [--out DIR]
"""

from __future__ import annotations

import math
import sys

import numpy as np

import _common as C

NAME = "settle"
G = 980.0
S_CM = 2.0


def free_pivot_rate(half_side_cm: float = 1.0, g: float = G) -> float:
    """Edge-balance rate with a frictionless floor: only the CM height couples, I_cm = m s²/6.

    At small tilt φ the CM moves vertically only (no horizontal force), so the kinetic energy is
    ½ I_cm φ'² (+ O(φ²)), and λ² = m g r / I_cm with r = s/√2.
    """
    s = 2.0 * half_side_cm
    return math.sqrt(g * (s / math.sqrt(2.0)) / (s * s / 6.0))


#: (key, preset, integrator, borders in the full run, in the quick run, description)
RUNS = (
    ("seed", "seed", None, 40, 3, "the program: seed preset, semi-implicit Euler, dt = 1 ms"),
    ("seed-substep", "seed", "contact-substep", 30, 2, "the same model integrated accurately (contact-substep RK4)"),
    ("physical-substep", "physical", "contact-substep", 30, 2,
     "the physical preset (per-node Coulomb friction), contact-substep RK4"),
)


def borders(st, preset: str, integrator, n_borders: int, grid_window, res):
    """Random face-neighbour pairs of a grid whose outcomes differ (both settled)."""
    kw = {}
    if preset != "seed":
        kw["preset"] = preset
    if integrator is not None:
        kw["integrator"] = integrator
    s = st.sample(grid_window, res, **kw)
    g = s.labels
    ax, ay = s.axes
    pairs = []
    for off in ((1, 0), (0, 1)):
        a = g[: g.shape[0] - off[0], : g.shape[1] - off[1]]
        b = g[off[0]:, off[1]:]
        ii, jj = np.nonzero((a != b) & (a > 0) & (b > 0))
        for i, j in zip(ii, jj):
            pairs.append(((ax[i], ay[j]), (ax[i + off[0]], ay[j + off[1]])))
    pick = st.rng.choice(len(pairs), size=min(n_borders, len(pairs)), replace=False)
    return s, [pairs[q] for q in pick]


def fit_border(classify, settle, pa, pb, dists):
    from dicetrace.analysis import bisect_boundary, fit_settle_divergence, settle_profile

    br = bisect_boundary(classify, pa, pb, tol=1e-12)
    prof = settle_profile(settle, br, dists)
    out = {"p_lo": br.p_lo, "p_hi": br.p_hi, "width": br.width, "label_lo": br.label_lo, "label_hi": br.label_hi,
           "n_evals": br.n_evals, "profile": prof}
    for side, lab in (("lo", br.label_lo), ("hi", br.label_hi)):
        p = prof[prof.side == side]
        ok = (p.label == lab).to_numpy()
        out[f"{side}_n_ok"] = int(ok.sum())
        if ok.sum() >= 6:
            f = fit_settle_divergence(p.d[ok], p.t_settle_s[ok])
            out[side] = {"lambda": f.lambda_per_s, "lambda_stderr": f.lambda_stderr, "t0": f.t0_s, "r": f.rvalue}
        else:
            out[side] = None
    return out


def summarise(fits: list[dict]) -> dict:
    lam, r = [], []
    for f in fits:
        for side in ("lo", "hi"):
            if f.get(side):
                lam.append(f[side]["lambda"])
                r.append(f[side]["r"])
    lam, r = np.array(lam), np.array(r)
    clean = lam[r < -0.995]
    out = {"n_fits": int(len(lam)), "n_clean": int(len(clean))}
    if len(lam):
        out.update(median=float(np.median(lam)), q25=float(np.quantile(lam, 0.25)),
                   q75=float(np.quantile(lam, 0.75)))
        # bootstrap stderr of the median
        rng = np.random.default_rng(0)
        bs = [np.median(lam[rng.integers(0, len(lam), len(lam))]) for _ in range(500)]
        out["median_stderr"] = float(np.std(bs, ddof=1)) if len(lam) > 1 else None
    if len(clean):
        out.update(clean_mean=float(clean.mean()),
                   clean_stderr=float(clean.std(ddof=1) / math.sqrt(len(clean))) if len(clean) > 1 else None,
                   clean_min=float(clean.min()), clean_max=float(clean.max()))
    out["all"] = lam
    out["r"] = r
    return out


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib.pyplot as plt

    from dicetrace.analysis import edge_balance_rate
    from dicetrace.analysis.plot import plot_settle_map
    from dicetrace.analysis.simulator import classify_on_slice, settle_on_slice

    lam_fixed = edge_balance_rate()
    lam_free = free_pivot_rate()
    st.results["predicted"] = {"fixed_pivot_per_s": lam_fixed, "free_pivot_per_s": lam_free}

    # settle-time maps
    res = st.res(401, 41)
    for w in ("red-sea", "home"):
        s = st.sample(w, res)
        fig = plot_settle_map(s.labels, s.t_settle_s, extent=s.extent,
                              title=f"{w}: outcome shaded by settle time ({res}²)")
        st.save_fig(fig, f"g_settle_map_{w}", caption=f"Settle-time map of the {w} window: darker = slower; "
                    "cell borders show as dark seams where the die balances on an edge.")
        st.results[f"map_{w}"] = {"res": res, "mean_settle_s": float(s.t_settle_s.mean()),
                                  "max_settle_s": float(s.t_settle_s.max()),
                                  "p99_settle_s": float(np.quantile(s.t_settle_s, 0.99))}

    dists = np.logspace(-11, -4, st.pick(22, 8))
    st.results["distances"] = dists
    runs = {}
    for key, preset, integ, nf, nq, desc in RUNS:
        kw = {"integrator": integ} if integ else {}
        classify = classify_on_slice("seed", preset=preset, **kw)
        settle = settle_on_slice("seed", preset=preset, **kw)
        _, pairs = borders(st, preset, integ, st.pick(nf, nq), C.window_ranges("red-sea-2"), st.pick(101, 21))
        fits = []
        for pa, pb in pairs:
            fits.append(fit_border(classify, settle, np.array(pa), np.array(pb), dists))
        summ = summarise(fits)
        runs[key] = {"fits": fits, "summary": summ, "description": desc}
        st.log(f"{key}: λ median {summ.get('median', float('nan')):.2f} /s over {summ['n_fits']} fits, "
               f"clean mean {summ.get('clean_mean', float('nan')):.2f} ({summ['n_clean']})")

    # figure: example profiles and the distribution of λ
    fig, axes = plt.subplots(1, 2, figsize=(11.5, 4.3))
    fits = runs["seed"]["fits"]
    shown = 0
    for f in fits:
        if shown >= 4 or not (f.get("lo") and f.get("hi")):
            continue
        prof = f["profile"]
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
        lam = runs[key]["summary"]["all"]
        axes[1].hist(np.clip(lam, bins[0], bins[-1]), bins=bins, alpha=0.5, color=col, label=key)
    axes[1].axvline(lam_fixed, color="k", ls="--", label=f"held pivot {lam_fixed:.1f} /s")
    axes[1].axvline(lam_free, color="k", ls=":", label=f"sliding pivot {lam_free:.1f} /s")
    axes[1].set_xlabel("fitted λ / (1/s)")
    axes[1].set_ylabel("border sides")
    axes[1].set_title("Fitted divergence rates")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    st.save_fig(fig, "g_settle_divergence", caption="Left: settle time against the distance from four located "
                "borders, both sides, with T = T0 − ln(d)/λ fits. Right: λ of every side fitted (clipped to "
                "10–60 /s) for the three runs, against the two predictions.")

    rows = []
    for key, *_ in RUNS:
        preset = key
        sm = runs[key]["summary"]
        rows.append({"preset": key, "desc": runs[key]["description"], "n": sm["n_fits"], "med": C.pm(sm.get("median", math.nan),
                                                                      sm.get("median_stderr"), ".1f"),
                     "iqr": f"{sm.get('q25', math.nan):.1f}–{sm.get('q75', math.nan):.1f}",
                     "nc": sm["n_clean"], "cm": C.pm(sm.get("clean_mean", math.nan), sm.get("clean_stderr"), ".1f")})
        # keep the JSON light: drop the profiles
        for f in runs[key]["fits"]:
            prof = f.pop("profile")
            f["t_range_s"] = [float(prof.t_settle_s.min()), float(prof.t_settle_s.max())]
    st.results["tables"]["lambda"] = C.md_table(rows, [
        ("preset", "run", ""), ("desc", "model and integrator", ""), ("n", "sides fitted", "d"), ("med", "median λ (1/s) ± bootstrap se", ""),
        ("iqr", "interquartile range", ""), ("nc", "clean fits (r < −0.995)", "d"),
        ("cm", "mean λ of clean fits ± se", "")])
    st.results["runs"] = runs
    st.results["res"] = res
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])
