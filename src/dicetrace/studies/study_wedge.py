"""Study h (wedge): the ball–hill wedge (writeup 4.2 and appendix 8.1).

The phase portrait (θ, Ω) of a ball on a circular hill with its four
separatrices through the saddle (π/2, 0), the outcome (over / back) of every
phase-space state, and the transit time near the separatrix: integrated
exactly (DOP853), it diverges like T ≈ T0 − ln(δ)/λ with λ = √(g/R), the
saddle's rate. Fitting it with the same ``fit_settle_divergence`` used on
the die (study g) checks the method on a system with a known answer.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.analysis import (
    ball_hill_outcome, ball_hill_saddle_rate, ball_hill_separatrices, ball_hill_transit_time, fit_settle_divergence,
)
from dicetrace.analysis.plot import plot_ball_hill_phase_portrait
from dicetrace.studies.context import Computed, Context, Output
from dicetrace.studies.text import md_table, pm

NAME = "wedge"
G, R_CM = 980.0, 1.0
#: Start angle of the transit-time runs, rad.
THETA0 = math.pi / 4


def compute(ctx: Context) -> Computed:
    k = G / R_CM
    # outcome map of the phase plane
    n = ctx.pick(301, 61)
    wmax = 1.6 * math.sqrt(2 * k)
    th, om = np.linspace(0, math.pi, n), np.linspace(-wmax, wmax, n)
    T, W = np.meshgrid(th, om, indexing="ij")
    outcome = ball_hill_outcome(T, W, g=G, radius_cm=R_CM)
    # transit time near the separatrix from THETA0, both sides
    om_sep = math.sqrt(2 * k * (1 - math.sin(THETA0)))
    deltas = np.logspace(-10, -2, ctx.pick(17, 6))
    rows = []
    for side, sign in (("over", 1.0), ("back", -1.0)):
        ts = np.array([ball_hill_transit_time(THETA0, om_sep * (1 + sign * d), g=G, radius_cm=R_CM, t_max=5.0)[0]
                       for d in deltas])
        fit = fit_settle_divergence(deltas, ts)
        rows.append({"side": side, "lambda": fit.lambda_per_s, "lambda_stderr": fit.lambda_stderr,
                     "r": fit.rvalue, "t": ts})
    results = {"saddle_rate_per_s": ball_hill_saddle_rate(g=G, radius_cm=R_CM), "fits": rows, "deltas": deltas}
    return Computed(results, {"outcome": outcome, "wmax": wmax})


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing
    from matplotlib.colors import ListedColormap

    R, wmax = c.results, c.plot["wmax"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    plot_ball_hill_phase_portrait(g=G, radius_cm=R_CM, ax=axes[0])
    axes[0].set_title("Ball–hill phase portrait (normalised field) and separatrices")
    axes[1].imshow(c.plot["outcome"].T, origin="lower", extent=(0, math.pi, -wmax, wmax), aspect="auto",
                   cmap=ListedColormap(["#9ecae1", "0.5", "#fdae6b"]), vmin=-1.5, vmax=1.5, interpolation="nearest")
    for name, curve in ball_hill_separatrices(g=G, radius_cm=R_CM).items():
        axes[1].plot(curve[:, 0], curve[:, 1], "-" if name.startswith("stable") else "--", color="k", lw=1.2)
    axes[1].plot([math.pi / 2], [0], "ko")
    out.save_plot(fig, axes[1], "h_ball_hill", xlabel="θ / rad", ylabel="Ω / (rad/s)", legend=None,
                  title="Outcome: over the top (orange) or back (blue)",
                  caption="Left: the ball–hill phase portrait with its four separatrices (solid: stable, arriving "
                  "at the saddle; dashed: unstable). Right: the outcome of every state; the stable separatrices "
                  "are the borders between the two cells.")
    lam = R["saddle_rate_per_s"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for r, mk in zip(R["fits"], ("o", "s")):
        ax.semilogx(R["deltas"], r["t"], mk, ms=4, label=f"{r['side']}: λ = {r['lambda']:.3f} ± {r['lambda_stderr']:.3f} /s")
    out.save_plot(fig, ax, "h_transit", xlabel="δ: relative distance of Ω0 from the separatrix",
                  ylabel="transit time / s", title=f"Ball–hill transit time (√(g/R) = {lam:.3f} /s)", legend=8,
                  caption="Transit time of the ball against the distance from the separatrix, both sides; the "
                  "slope gives the saddle rate.")
    out.tables["fits"] = md_table(
        [{"side": r["side"], "lam": pm(r["lambda"], r["lambda_stderr"], ".4f"), "r": r["r"], "pred": lam}
         for r in R["fits"]], [("side", "side", ""), ("lam", "fitted λ (1/s)", ""), ("r", "r", ".6f"),
                               ("pred", "√(g/R) (1/s)", ".4f")])
