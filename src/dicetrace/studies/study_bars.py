"""Study bars: the two-dimensional limit: long bars against Pender & Uhrin's formula.

A bar much longer than its section almost never stands on an end: it rolls
about its long axis like a two-dimensional die, a rectangle of sides k and l.
Pender & Uhrin (arXiv:1407.6307) give a closed formula for the ratio of the
probabilities of its two kinds of side,
:func:`dicetrace.analysis.fairness.pender_uhrin_ratio`; their own measured rolls
could not be read (:data:`dicetrace.analysis.dice_data.NOT_TRANSCRIBED`), so the
formula alone is held to the simulation here.

Everything below was fixed before any simulated ratio was compared with the formula:

- the model: the ``physical`` preset as it is (its ground law, friction μ = 1.2 and
  tolerance schedule; ``contact-tsit5``), uniform bodies, as in the cuboid study
  (:mod:`dicetrace.studies.study_cuboids`);
- the bars: half-extents (``HALF_LENGTH_CM``, k/2, l/2) with k = ``K_CM`` (the narrow
  side of the section, along the body's y axis) and l = (l/k)·k along z, for the side
  ratios ``RATIOS``; the length 2·``HALF_LENGTH_CM`` is 5 times the largest section
  side (faces 1 and 6 are the ends; 2 and 5 the wide sides, normal to y; 3 and 4 the
  narrow ones);
- the throw: :data:`dicetrace.throws.CASUAL`, ``N_MAIN`` throws per bar, and the throw's
  systematic :data:`~dicetrace.throws.GENTLE` and :data:`~dicetrace.throws.VIGOROUS`,
  ``N_SYST`` each;
- the length's systematic: the bar of ratio ``LONG_RATIO`` again, twice as long
  (``LONG_HALF_LENGTH_CM``), ``N_MAIN`` casual throws.

A throw ends *wide* when a wide side is down (a wide face up: faces 2 or 5), *narrow*
on a narrow side (faces 3 or 4), on an *end* (faces 1 or 6), on an edge (outcome 0)
or at the time cap; every kind is counted and reported.  R = wide/narrow, and p =
wide/(wide + narrow) with its 95 % Wilson interval (R's interval is p's, mapped by
R = p/(1 − p)).  Pender & Uhrin's p is R_PU/(1 + R_PU) (:func:`~dicetrace.analysis.fairness.pender_uhrin_p`
with k the narrow and l the wide side); z = (p − p_PU)/√(p_PU(1 − p_PU)/n) at each
ratio above 1, and χ² = Σ z² over them (no parameter fitted).  At l/k = 1 the
formula gives 1 by symmetry, so that point is a check of the code's symmetry, not of
the formula.

The verdict on the formula, at the stated errors: **supported** if the χ² of every
throw model passes (p-value ≥ ``PASS_P``) at the binomial errors; **refuted** if the
casual throws fail even with the systematic (half the throw models' spread of p at
each ratio, and the length's shift of p at its ratio) added to the binomial error in
quadrature; **undetermined** otherwise (the deviation is within what the throw or the
length moves).

Run it with ``dicetrace analyze bars --out analysis/bars`` (it writes ``bars.csv``,
``results.json``, ``bars.md`` and ``bars.png``; ``--quick`` for a small check, into
``./dicetrace-results/bars`` by default).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from dicetrace.analysis.fairness import pender_uhrin_p, pender_uhrin_ratio
from dicetrace.analysis.grouping import wilson_interval
from dicetrace.compile_clock import CompileClock, time_text
from dicetrace.params import make_config
from dicetrace.simulate import simulate_batch
from dicetrace.studies.outputs import label_axes, write_figure, write_text, written
from dicetrace.throws import CASUAL, GENTLE, VIGOROUS

#: The narrow side k of every bar's section, cm.
K_CM = 1.0
#: Side ratios l/k of the bars.
RATIOS = (1.0, 1.25, 1.5, 1.75, 2.0, 2.5)
#: Half the length of every bar, cm: 5 times the largest half side of a section (2.5·K_CM/2).
HALF_LENGTH_CM = 5 * 0.5 * K_CM * max(RATIOS)
#: The length's systematic: the bar of this ratio, twice as long.
LONG_RATIO = 1.5
LONG_HALF_LENGTH_CM = 2 * HALF_LENGTH_CM
N_MAIN = 20_000
N_SYST = 5_000
SEED = 14076307
QUICK = dict(n_main=300, n_syst=100, ratios=(1.0, 2.0))
#: The χ² p-value at and above which a throw model's ratios pass.
PASS_P = 0.05
#: Faces up of each way a bar ends (docs/model.md §3: faces 2, 5 normal to y, 3, 4 normal to z, 1, 6 the ends).
WIDE, NARROW, END = (2, 5), (3, 4), (1, 6)

__all__ = ["K_CM", "RATIOS", "HALF_LENGTH_CM", "LONG_RATIO", "LONG_HALF_LENGTH_CM", "N_MAIN", "N_SYST", "QUICK",
           "half_extents", "counts", "study", "summarise", "render"]


def half_extents(ratio: float, half_length_cm: float = HALF_LENGTH_CM) -> tuple[float, float, float]:
    """The bar of side ratio l/k = ``ratio``: half-extents (length, k, l)/2 along the body's x, y, z, cm."""
    return (float(half_length_cm), 0.5 * K_CM, 0.5 * K_CM * float(ratio))


def counts(outcome) -> dict:
    """How a batch of bars ended: wide, narrow, end, edge, unsettled; p = wide/(wide + narrow) with its Wilson
    interval, R = wide/narrow with the interval mapped from p's (NaN where undefined)."""
    o = np.asarray(outcome)
    wide = int(np.isin(o, WIDE).sum())
    narrow = int(np.isin(o, NARROW).sum())
    out = {"wide": wide, "narrow": narrow, "end": int(np.isin(o, END).sum()), "edge": int(np.sum(o == 0)),
           "unsettled": int(np.sum(o < 0)),
           "by_face": [int(np.sum(o == f)) for f in range(1, 7)]}
    n = wide + narrow
    if n:
        lo, hi = (float(v) for v in wilson_interval(wide, n))
        p = wide / n
    else:
        lo = hi = p = math.nan

    def ratio(q: float) -> float:
        return q / (1.0 - q) if q < 1 else math.inf

    out.update(n=n, p=p, ci_low=lo, ci_high=hi, R=ratio(p) if n else math.nan, R_low=ratio(lo) if n else math.nan,
               R_high=ratio(hi) if n else math.nan)
    return out


def _run(ratio: float, throw, n: int, seed: int, threads, half_length_cm: float = HALF_LENGTH_CM):
    cfg = make_config("physical", half_extents_cm=half_extents(ratio, half_length_cm))
    t = throw.sample(n, cfg, seed)
    return simulate_batch(t.ics, config=cfg, orientations=t.orientations, heights_cm=t.heights_cm, threads=threads)


def study(*, n_main: int = N_MAIN, n_syst: int = N_SYST, ratios=RATIOS, threads=None, say=print) -> dict:
    """Every run of the study (see the module docstring) as plain data: one row per bar and throw model."""
    rows = []
    runs = [(r, throw, n, HALF_LENGTH_CM) for r in ratios
            for throw, n in ((CASUAL, n_main), (GENTLE, n_syst), (VIGOROUS, n_syst))]
    long_ratio = LONG_RATIO if LONG_RATIO in ratios else ratios[-1]
    runs.append((long_ratio, CASUAL, n_main, LONG_HALF_LENGTH_CM))
    throws_s = []
    for j, (r, throw, n, half_len) in enumerate(runs):
        t0 = time.perf_counter()
        with CompileClock() as clock:
            res = _run(r, throw, n, SEED + j, threads, half_len)
        wall = time.perf_counter() - t0
        variant = throw.name if half_len == HALF_LENGTH_CM else f"{throw.name}, twice as long"
        k, l = K_CM, K_CM * r
        rows.append({"ratio": float(r), "variant": variant, "throw": throw.name,
                     "half_extents_cm": list(half_extents(r, half_len)), "throws": n, **counts(res.outcome),
                     "R_pu": float(pender_uhrin_ratio(k, l)), "p_pu": float(pender_uhrin_p(k, l)),
                     "mean_settle_time_s": float(np.mean(res.t_settle_s[res.status_code == 0])),
                     "wall_s": wall})
        if clock.seconds < 0.1 * wall:
            throws_s.append(n / wall)
        say(f"l/k {r:g} ({variant}) × {n}: R = {rows[-1]['R']:.3f} against {rows[-1]['R_pu']:.3f}, "
            f"{rows[-1]['end']} on an end ({time_text(wall, clock.seconds, '.0f')})")
    return {"rows": rows, "ratios": [float(r) for r in ratios], "long_ratio": float(long_ratio),
            "throws_per_s": float(np.median(throws_s)) if throws_s else math.nan}


def _z(p: float, p0: float, n: int, sys: float = 0.0) -> float:
    sigma = math.sqrt(p0 * (1.0 - p0) / n + sys * sys) if n else math.nan
    return (p - p0) / sigma if sigma > 0 else math.nan


def summarise(data: dict) -> dict:
    """z and χ² of each throw model against the formula, the systematics, the symmetry checks and the verdict."""
    from scipy import stats

    rows = pd.DataFrame(data["rows"])
    tested = [r for r in data["ratios"] if r != 1.0]
    out: dict = {"models": {}}
    main = rows[~rows["variant"].str.contains("long")]
    for name, g in main.groupby("variant", sort=False):
        g = g.set_index("ratio")
        z = [_z(g.loc[r, "p"], g.loc[r, "p_pu"], int(g.loc[r, "n"])) for r in tested]
        chi2 = float(np.nansum(np.square(z)))
        out["models"][name] = {"z": z, "chi2": chi2, "dof": len(tested),
                               "p_value": float(stats.chi2.sf(chi2, len(tested))) if tested else math.nan,
                               "R_over_pu": [float(g.loc[r, "R"] / g.loc[r, "R_pu"]) for r in tested]}
        out["models"][name]["passes"] = bool(out["models"][name]["p_value"] >= PASS_P)
    wide = main.pivot(index="ratio", columns="variant", values="p")
    spread = (wide.max(axis=1) - wide.min(axis=1))
    out["throw_spread_p"] = [float(spread.loc[r]) for r in data["ratios"]]
    Rw = main.pivot(index="ratio", columns="variant", values="R")
    out["throw_spread_R"] = [float(Rw.loc[r].max() - Rw.loc[r].min()) for r in data["ratios"]]
    # is the throw's effect resolved? Pearson's χ² of homogeneity of the three throw models, bar by bar, summed
    chi2_h, dof_h = 0.0, 0
    for _, g in main.groupby("ratio"):
        table = np.array([g["wide"].to_numpy(), g["narrow"].to_numpy()])
        if (table.sum(axis=0) > 0).all() and (table.sum(axis=1) > 0).all():
            res = stats.chi2_contingency(table, correction=False)
            chi2_h, dof_h = chi2_h + float(res.statistic), dof_h + int(res.dof)
    out["throw_homogeneity"] = {"chi2": chi2_h, "dof": dof_h,
                                "p_value": float(stats.chi2.sf(chi2_h, dof_h)) if dof_h else math.nan}
    # the length: the same ratio, casual throws, twice as long
    lr = data["long_ratio"]
    short = main[(main["ratio"] == lr) & (main["variant"] == CASUAL.name)].iloc[0]
    long = rows[rows["variant"].str.contains("long")].iloc[0]
    dp = float(long["p"] - short["p"])
    se = math.sqrt(short["p"] * (1 - short["p"]) / short["n"] + long["p"] * (1 - long["p"]) / long["n"])
    out["length"] = {"ratio": lr, "p_short": float(short["p"]), "p_long": float(long["p"]), "shift_p": dp,
                     "shift_p_stderr": se, "z": dp / se if se > 0 else math.nan,
                     "R_short": float(short["R"]), "R_long": float(long["R"]),
                     "shift_R": float(long["R"] - short["R"])}
    # the casual χ² with the systematic: half the throw models' spread, and the length's shift at its ratio
    cas = main[main["variant"] == CASUAL.name].set_index("ratio")
    z_sys = []
    for r in tested:
        sys = 0.5 * float(spread.loc[r])
        if r == lr:
            sys = math.hypot(sys, dp)
        z_sys.append(_z(cas.loc[r, "p"], cas.loc[r, "p_pu"], int(cas.loc[r, "n"]), sys))
    chi2_s = float(np.nansum(np.square(z_sys)))
    out["casual_with_systematic"] = {"z": z_sys, "chi2": chi2_s, "dof": len(tested),
                                     "p_value": float(stats.chi2.sf(chi2_s, len(tested))) if tested else math.nan}
    # the symmetry checks: the square bar's R, and each pair of opposite faces
    sq = cas.loc[1.0] if 1.0 in cas.index else None
    if sq is not None:
        out["square"] = {"R": float(sq["R"]), "R_low": float(sq["R_low"]), "R_high": float(sq["R_high"]),
                         "one_inside": bool(sq["R_low"] <= 1.0 <= sq["R_high"])}
    pair_chi2, pair_dof = 0.0, 0
    for _, row in main.iterrows():  # faces 2 vs 5 and 3 vs 4 (and 1 vs 6) alike: a binomial χ² per pair with counts
        f = row["by_face"]
        for a, b in ((1, 4), (2, 3), (0, 5)):
            if f[a] + f[b] > 0:
                pair_chi2 += (f[a] - f[b]) ** 2 / (f[a] + f[b])
                pair_dof += 1
    out["opposite_faces"] = {"chi2": pair_chi2, "dof": pair_dof,
                             "p_value": float(stats.chi2.sf(pair_chi2, pair_dof)) if pair_dof else math.nan}
    out["ends_total"] = int(rows["end"].sum())
    out["edge_total"] = int(rows["edge"].sum())
    out["unsettled_total"] = int(rows["unsettled"].sum())
    out["throws_total"] = int(rows["throws"].sum())
    ratio_pu = out["models"][CASUAL.name]["R_over_pu"] if tested else []
    out["casual_R_over_pu_min"] = float(min(ratio_pu)) if ratio_pu else math.nan
    out["casual_R_over_pu_max"] = float(max(ratio_pu)) if ratio_pu else math.nan
    zc = out["models"][CASUAL.name]["z"] if tested else []
    below = sum(1 for z in zc if z < -1.96)
    above = sum(1 for z in zc if z > 1.96)
    out["casual_below"], out["casual_above"] = below, above
    if tested and below == len(zc):
        out["direction"] = f"below the formula's at each of the {len(zc)} side ratios above 1 tested (nearer to 1)"
    elif tested and above == len(zc):
        out["direction"] = f"above the formula's at each of the {len(zc)} side ratios above 1 tested (further from 1)"
    else:
        out["direction"] = (f"below the formula's at {below} and above it at {above} of the {len(zc)} side ratios "
                            "above 1 (|z| > 1.96), within its binomial error at the others")
    passes = [out["models"][name]["passes"] for name in (CASUAL.name, GENTLE.name, VIGOROUS.name)
              if name in out["models"]]
    if passes and all(passes):
        out["verdict"] = "supported"
    elif out["casual_with_systematic"]["p_value"] < PASS_P:
        out["verdict"] = "refuted"
    else:
        out["verdict"] = "undetermined"
    if len(tested) < len(RATIOS) - 1 or int(rows["throws"].min()) < N_SYST:
        out["verdict"] = "none (a reduced run: too few bars or throws for one)"
    return out


def _md_tables(data: dict, summary: dict) -> dict[str, str]:
    rows = pd.DataFrame(data["rows"])
    by = {name: g.set_index("ratio") for name, g in rows.groupby("variant", sort=False)}
    main = ["| l/k | Pender & Uhrin R | casual R (95 %) | z | gentle R | z | vigorous R | z | "
            "ends / edge / unsettled (casual) |", "|---|---|---|---|---|---|---|---|---|"]
    tested = [r for r in data["ratios"] if r != 1.0]
    for r in data["ratios"]:
        cells = []
        for name in (CASUAL.name, GENTLE.name, VIGOROUS.name):
            row = by[name].loc[r]
            z = summary["models"][name]["z"][tested.index(r)] if r in tested else None
            cells.append(f"{row['R']:.3f} ({row['R_low']:.3f}–{row['R_high']:.3f}, n {int(row['n'])})")
            cells.append("—" if z is None else f"{z:+.1f}")
        c = by[CASUAL.name].loc[r]
        main.append(f"| {r:g} | {c['R_pu']:.3f} | {' | '.join(cells)} | {int(c['end'])} / {int(c['edge'])} / "
                    f"{int(c['unsettled'])} |")
    chi = ["| throw model | χ² | dof | p-value |", "|---|---|---|---|"]
    for name, m in summary["models"].items():
        chi.append(f"| {name} | {m['chi2']:.1f} | {m['dof']} | {m['p_value']:.2g} |")
    s = summary["casual_with_systematic"]
    chi.append(f"| casual, with the throw's and the length's systematic | {s['chi2']:.1f} | {s['dof']} | "
               f"{s['p_value']:.2g} |")
    return {"ratios": "\n".join(main), "chi2": "\n".join(chi)}


def render(data: dict, summary: dict, out: Path, command: str, wall_s: float) -> dict[str, Path]:
    """``bars.csv``, ``results.json``, ``bars.md`` and ``bars.png`` in ``out``; their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    rows = pd.DataFrame(data["rows"])
    with written(out / "bars.csv", "table") as tmp:
        rows.drop(columns=["by_face", "half_extents_cm"]).assign(
            half_length_cm=[h[0] for h in rows["half_extents_cm"]]).to_csv(tmp, index=False)
    tables = _md_tables(data, summary)
    caption = (f"R = P(wide side)/P(narrow side) of long bars (section k × l, k = {K_CM:g} cm, "
               f"{2 * HALF_LENGTH_CM:g} cm long), 95 % intervals, against Pender & Uhrin's formula (line)")
    results = {"command": command, "wall_s": wall_s, "seed": SEED, "k_cm": K_CM, "half_length_cm": HALF_LENGTH_CM,
               "long_half_length_cm": LONG_HALF_LENGTH_CM, "n_main": int(rows["throws"].max()), "pass_p": PASS_P, **data,
               "summary": summary, "tables": tables,
               "figures": {"bars": {"path": f"{out.name}/bars.png", "caption": caption}}}
    with written(out / "results.json", "results") as tmp:
        Path(tmp).write_text(json.dumps(results, indent=1))
    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    fine = np.linspace(1.0, max(data["ratios"]) * 1.04, 200)
    ax.plot(fine, pender_uhrin_ratio(K_CM, K_CM * fine), "k-", lw=1, label="Pender & Uhrin (formula)")
    for (name, g), colour, shift in zip(rows.groupby("variant", sort=False), ("C0", "C2", "C3", "C1"),
                                        (0.0, -0.015, 0.015, 0.03)):
        ax.errorbar(g["ratio"] + shift, g["R"], yerr=[g["R"] - g["R_low"], g["R_high"] - g["R"]], fmt="o" if
                    "long" not in name else "D", ms=4, color=colour, capsize=2, label=f"physical, {name}")
    ax.set_yscale("log")
    label_axes(ax, xlabel="l / k (wide side over narrow side of the section)", ylabel="R = P(wide) / P(narrow)",
               title="Long bars: the two-dimensional die against Pender & Uhrin", legend=8)
    fig.tight_layout()
    write_figure(fig, out / "bars.png", dpi=120)
    write_text(out / "bars.md", _markdown(data, summary, tables, command, wall_s), "summary")
    return {"csv": out / "bars.csv", "json": out / "results.json", "summary": out / "bars.md",
            "figure": out / "bars.png"}


def _markdown(data: dict, summary: dict, tables: dict, command: str, wall_s: float) -> str:
    ln = summary["length"]
    h = summary["throw_homogeneity"]
    lines = [
        "# Long bars: the two-dimensional die against Pender & Uhrin's formula", "",
        f"Command: `{command}` ({wall_s:.0f} s wall on this machine, {data['throws_per_s']:.0f} throws/s). Model: the "
        f"`physical` preset as it is (contact-tsit5, its tolerance schedule), uniform bars {2 * HALF_LENGTH_CM:g} cm "
        f"long of section k × l, k = {K_CM:g} cm; throws: dicetrace.throws (casual; gentle and vigorous for the "
        "throw's systematic). R: throws that ended on a wide side over those on a narrow side (95 % interval from "
        "the Wilson interval of their share); z: the share against the formula's at its binomial error.", "",
        tables["ratios"], "", tables["chi2"], "",
        f"Ends: {summary['ends_total']} of {summary['throws_total']} throws ended on an end, {summary['edge_total']} "
        f"on an edge, {summary['unsettled_total']} at the time cap.",
    ]
    if "square" in summary:
        sq = summary["square"]
        lines.append(f"The square bar (l/k = 1): R = {sq['R']:.3f} ({sq['R_low']:.3f}–{sq['R_high']:.3f}), 1 "
                     f"{'inside' if sq['one_inside'] else 'outside'} its interval. Opposite faces alike (every bar "
                     f"and throw model): χ² {summary['opposite_faces']['chi2']:.1f} on "
                     f"{summary['opposite_faces']['dof']} dof, p = {summary['opposite_faces']['p_value']:.2g}.")
    lines += [
        "", f"The length: at l/k = {ln['ratio']:g}, twice as long a bar gives R = {ln['R_long']:.3f} against "
        f"{ln['R_short']:.3f} (shift of the wide share {ln['shift_p']:+.4f} ± {ln['shift_p_stderr']:.4f}, "
        f"z = {ln['z']:.1f}). The throw: the three throw models' shares are "
        f"{'consistent with one another' if h['p_value'] >= PASS_P else 'not consistent with one another'} "
        f"(Pearson's χ² of homogeneity {h['chi2']:.1f} on {h['dof']} dof, p = {h['p_value']:.2g}).", "",
        f"The casual R is {summary['casual_R_over_pu_min']:.2f}–{summary['casual_R_over_pu_max']:.2f} times the "
        f"formula's over the bars with l/k > 1: {summary['direction']}.", "",
        f"Verdict on Pender & Uhrin's formula as a prediction of `physical`'s long bars: **{summary['verdict']}** "
        f"(supported if every throw model passes at χ² p ≥ {PASS_P:g} at the binomial errors; refuted if the "
        "casual throws fail even with the throw's and the length's systematic added; undetermined otherwise). "
        "Pender & Uhrin's own measured rolls could not be read, so only their formula is compared.", "",
    ]
    return "\n".join(lines)


def rerender(out: Path) -> dict[str, Path]:
    """Summarise and render again from ``out``'s ``results.json`` (no simulation)."""
    out = Path(out)
    res = json.loads((out / "results.json").read_text())
    data = {k: res[k] for k in ("rows", "ratios", "long_ratio", "throws_per_s")}
    return render(data, summarise(data), out, res["command"], res["wall_s"])
