"""Study h: the ball–hill wedge (writeup 4.2 and appendix 8.1).

The phase portrait (θ, Ω) of a ball on a circular hill with its four
separatrices through the saddle (π/2, 0), the outcome (over / back) of every
phase-space state, and the transit time near the separatrix: integrated
exactly (DOP853), it diverges like T ≈ T0 − ln(δ)/λ with λ = √(g/R), the
saddle's rate. Fitting it with the same ``fit_settle_divergence`` used on
the die (study g) checks the method on a system with a known answer.

    python analysis/h_wedge.py [--quick] [--out DIR]
"""

from __future__ import annotations

import math
import sys

import numpy as np

import _common as C

NAME = "wedge"


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib.pyplot as plt

    from dicetrace.analysis import (
        ball_hill_outcome,
        ball_hill_saddle_rate,
        ball_hill_separatrices,
        ball_hill_transit_time,
        fit_settle_divergence,
    )
    from dicetrace.analysis.plot import plot_ball_hill_phase_portrait

    g, R = 980.0, 1.0
    k = g / R
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    plot_ball_hill_phase_portrait(g=g, radius_cm=R, ax=axes[0])
    axes[0].set_title("Ball–hill phase portrait (normalised field) and separatrices")
    # outcome map of the phase plane
    n = st.pick(301, 61)
    th = np.linspace(0, math.pi, n)
    wmax = 1.6 * math.sqrt(2 * k)
    om = np.linspace(-wmax, wmax, n)
    T, W = np.meshgrid(th, om, indexing="ij")
    out = ball_hill_outcome(T, W, g=g, radius_cm=R)
    from matplotlib.colors import ListedColormap

    axes[1].imshow(out.T, origin="lower", extent=(0, math.pi, -wmax, wmax), aspect="auto",
                   cmap=ListedColormap(["#9ecae1", "0.5", "#fdae6b"]), vmin=-1.5, vmax=1.5, interpolation="nearest")
    for name, curve in ball_hill_separatrices(g=g, radius_cm=R).items():
        axes[1].plot(curve[:, 0], curve[:, 1], "-" if name.startswith("stable") else "--", color="k", lw=1.2)
    axes[1].plot([math.pi / 2], [0], "ko")
    axes[1].set_xlabel("θ / rad")
    axes[1].set_ylabel("Ω / (rad/s)")
    axes[1].set_title("Outcome: over the top (orange) or back (blue)")
    fig.tight_layout()
    st.save_fig(fig, "h_ball_hill", caption="Left: the ball–hill phase portrait with its four separatrices "
                "(solid: stable, arriving at the saddle; dashed: unstable). Right: the outcome of every state; "
                "the stable separatrices are the borders between the two cells.")

    # transit time near the separatrix from theta0 = pi/4, both sides
    th0 = math.pi / 4
    om_sep = math.sqrt(2 * k * (1 - math.sin(th0)))
    deltas = np.logspace(-10, -2, st.pick(17, 6))
    rows = []
    for side, sign in (("over", 1.0), ("back", -1.0)):
        ts = []
        for d in deltas:
            t, o = ball_hill_transit_time(th0, om_sep * (1 + sign * d), g=g, radius_cm=R, t_max=5.0)
            ts.append(t)
        ts = np.array(ts)
        fit = fit_settle_divergence(deltas, ts)
        rows.append({"side": side, "lambda": fit.lambda_per_s, "lambda_stderr": fit.lambda_stderr,
                     "r": fit.rvalue, "t": ts})
    lam = ball_hill_saddle_rate(g=g, radius_cm=R)
    st.results["saddle_rate_per_s"] = lam
    st.results["fits"] = rows
    st.results["deltas"] = deltas
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for r, mk in zip(rows, ("o", "s")):
        ax.semilogx(deltas, r["t"], mk, ms=4, label=f"{r['side']}: λ = {r['lambda']:.3f} ± {r['lambda_stderr']:.3f} /s")
    ax.set_xlabel("δ: relative distance of Ω0 from the separatrix")
    ax.set_ylabel("transit time / s")
    ax.set_title(f"Ball–hill transit time (√(g/R) = {lam:.3f} /s)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    st.save_fig(fig, "h_transit", caption="Transit time of the ball against the distance from the separatrix, "
                "both sides; the slope gives the saddle rate.")
    st.results["tables"]["fits"] = C.md_table(
        [{"side": r["side"], "lam": C.pm(r["lambda"], r["lambda_stderr"], ".4f"), "r": r["r"], "pred": lam}
         for r in rows], [("side", "side", ""), ("lam", "fitted λ (1/s)", ""), ("r", "r", ".6f"),
                          ("pred", "√(g/R) (1/s)", ".4f")])
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])
