"""Rendering of the work-precision study: its Markdown summary, its plot and its files (CSV, JSON).

:func:`write_study` writes what :func:`dicetrace.studies.study_accuracy.study`
computed: ``study.csv``, ``orders.csv``, ``reference.csv``, ``presets.json``
(both presets ran), ``work_precision.png`` and ``summary.md``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from dicetrace.params import INTEGRATORS
from dicetrace.studies.study_accuracy import (
    BASELINE_INTEGRATOR,
    FLOOR_REL,
    FLOOR_WINDOW,
    PERTURBATIONS,
    PRESETS,
    T_MAX_S,
    StudyResult,
)
from dicetrace.studies.outputs import write_figure, write_text, written
from dicetrace.studies.study_accuracy_grids import color
from dicetrace.studies.study_accuracy_budgets import best_within_budget, budget_table, cheapest_at_target, zero_floor_settings
from dicetrace.studies.text import fmt, grows, tol_text


def _fmt(v, spec=".3g"):
    return fmt(v, spec, missing="—")


def setting(r: dict) -> str:
    """A run's numerical setting as text: dt, and tol (and its growth) for the error-controlled integrators."""
    tol = tol_text(r)
    return f"dt = {r['dt_s']:g} s" + (f", tol = {tol}" if tol else "")


def summary_markdown(res: StudyResult, command: str) -> str:
    """The study's Markdown summary (tables and the best method per budget)."""
    lines = [
        "# Work-precision study of the integrators",
        "",
        f"Command: `{command}`",
        "",
        f"ICs: {res.n} seeded uniform points (seed {res.seed}) of the `{res.window}` window of the seed slice; "
        "the `physical` preset gets the same throws (L negated into its physical convention). "
        f"Time cap {T_MAX_S:g} s. CPU time: process time of `simulate_batch` on one numba thread after warm-up.",
        "",
        "## Reference and chaos floor",
        "",
        "| preset | reference | check at dt/2: outcome agreement | check: first-impact error (cm) | "
        "second reference | agreement of the two (95 % Wilson) | own floor (flips) | "
        "floor 1e-12 | floor 1e-9 | floor 1e-6 | mean settle time (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res.references:
        lines.append(
            f"| {r['preset']} | {r['integrator']} dt={r['dt_s']:g} s | {r['self_agreement']:.3f} | "
            f"{_fmt(r['check_first_impact_error_cm'], '.2e')} | {r['second_reference']} | "
            f"{r['references_agreement']:.3f} [{r['references_agreement_lo']:.3f}, {r['references_agreement_hi']:.3f}] | "
            f"{r['own_floor_flips']}/{r['own_floor_n']} | {r['chaos_floor_1e-12']:.3f} | "
            f"{r['chaos_floor_1e-09']:.3f} | {r['chaos_floor_1e-06']:.3f} | {r['mean_settle_time_s']:.3f} |"
        )
    pc = res.preset_comparison
    if pc:
        counts = lambda d: ", ".join(f"{f}: {c}" for f, c in d.items() if f > 0 or c)  # noqa: E731
        lines += [
            "",
            "`seed` against `physical` on the same throws (their references): "
            f"same outcome on {pc['same_outcome']:.3f} of the ICs (chance would be about 1/6); "
            f"mean settle time {pc['mean_settle_time_seed_s']:.3f} s (seed) against {pc['mean_settle_time_physical_s']:.3f} s "
            f"(physical; median ratio {pc['median_settle_time_ratio']:.2f}); contact-set changes "
            f"{pc['mean_contact_changes_seed']:.1f} against {pc['mean_contact_changes_physical']:.1f}. "
            f"Faces (seed) {counts(pc['outcome_counts_seed'])}; (physical) {counts(pc['outcome_counts_physical'])}.",
        ]
    lines += [
        "",
        "The chaos floor is the outcome agreement of the reference with itself when every IC is moved by a relative "
        "δ (random direction): no method can be expected to agree better than the floor at the size of its own error. "
        "The reference counts as converged when halving its step changes fewer outcomes than a 1e-9 perturbation does, "
        "and when a second reference from another integrator agrees with it as well.",
        "",
        "## Own numerical floor of each setting",
        "",
        f"Each setting, run on {_floor_n(res)} ICs of the `{FLOOR_WINDOW}` window (a resolved window, where the model's "
        f"outcome is continuous in the IC) and on the same ICs moved by a relative {FLOOR_REL:g}: the number of outcomes "
        "that change (column *own floor* below). A scheme can be discontinuous where the model is not (step-size "
        "decisions, contact events); a bisection to 1e-12 with a setting whose floor is not 0 measures the scheme.",
        "",
    ]
    for preset in _presets(res):
        zero = zero_floor_settings(res.rows, preset)
        mine = [r for r in res.rows if r["preset"] == preset]
        others = ", ".join(f"{r['integrator']} {setting(r)} ({r['own_floor_flips']})" for r in mine if r not in zero)
        lines.append(f"- `{preset}`, settings whose floor is 0 ({len(zero)} of {len(mine)}): {_settings_text(zero)}."
                     + (f" Not 0 (flips): {others}." if others else ""))
    lines += [
        "",
        "## All runs",
        "",
        "| preset | integrator | dt (s) | tol | CPU ms/IC | agreement | settle-time bias (s) | contact-count bias | "
        "first-impact error (cm) | free-flight energy drift | blow-ups | time caps | own floor (flips) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res.rows:
        lines.append(
            f"| {r['preset']} | {r['integrator']} | {r['dt_s']:g} | {tol_text(r) or '—'} | {r['cpu_ms_per_ic']:.3g} | "
            f"{r['outcome_agreement']:.3f} | {_fmt(r['settle_time_bias_s'], '+.4f')} | "
            f"{_fmt(r['contact_count_bias'], '+.2f')} | {_fmt(r['first_impact_error_cm'], '.2e')} | "
            f"{_fmt(r['free_flight_energy_drift'], '.1e')} | {r['blow_ups']} | {r['time_caps']} | "
            f"{r['own_floor_flips']}/{r['own_floor_n']} |"
        )
    lines += ["", "## Fitted convergence orders (first-impact error against dt; for contact-adaptive against tol)", ""]
    lines += ["| preset | integrator | declared order | against | fitted exponent |", "|---|---|---|---|---|"]
    for o in res.orders:
        lines.append(
            f"| {o['preset']} | {o['integrator']} | {o['declared_order']} | {o.get('against', 'dt')} | "
            f"{_fmt(o['fitted_order_first_impact'], '.2f')} |"
        )
    bt = budget_table(res)
    if bt:
        lines += [
            "",
            f"## At the seed's cost ({res.seed_cost_ms:.3g} ms per throw: `seed`, semi-implicit Euler, dt = 1 ms) and 10×",
            "",
            "Best run of each integrator whose CPU time per IC is within the budget.",
            "",
            "| preset | budget | integrator | dt (s) | tol | CPU ms/IC | agreement | settle-time bias (s) | own floor (flips) | "
            "floor 1e-12 | floor 1e-9 |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for b in bt:
            lines.append(
                f"| {b['preset']} | {b['budget']} | {b['integrator']} | {_fmt(b['dt_s'], 'g')} | {tol_text(b) or '—'} | "
                f"{_fmt(b['cpu_ms_per_ic'], '.3g')} | {_fmt(b['outcome_agreement'], '.3f')} | "
                f"{_fmt(b['settle_time_bias_s'], '+.4f')} | {_fmt(b['own_floor_flips'], 'd')} | "
                f"{b['chaos_floor_1e-12']:.3f} | {b['chaos_floor_1e-09']:.3f} |"
            )
    lines += ["", "## Best method for a time budget", ""]
    for preset in _presets(res):
        costs = sorted({r["cpu_ms_per_ic"] for r in res.rows if r["preset"] == preset})
        budgets = _budget_points(costs, res.seed_cost_ms)
        for bud in budgets:
            best = best_within_budget(res.rows, preset, None, bud)
            if best is None:
                lines.append(f"- `{preset}`, {bud:.3g} ms per throw: no run fits.")
            else:
                lines.append(
                    f"- `{preset}`, {bud:.3g} ms per throw: **{best['integrator']}** at {setting(best)} "
                    f"(agreement {best['outcome_agreement']:.3f}, {best['cpu_ms_per_ic']:.3g} ms)."
                )
    lines += _cheapest_lines(res)
    for note in res.notes:
        lines += ["", note]
    return "\n".join(lines) + "\n"


def _settings_text(rows: list[dict]) -> str:
    """Runs named compactly, per integrator: ``rk4 at dt = 0.002, 0.001 s``; ``contact-adaptive at dt = 0.001 s, tol = 1e-06, 1e-07``."""
    groups: dict[tuple, list[str]] = {}
    for r in rows:
        tol = tol_text(r)
        if tol:
            groups.setdefault((r["integrator"], f"dt = {r['dt_s']:g} s, tol = "), []).append(tol)
        else:
            groups.setdefault((r["integrator"], "dt = "), []).append(f"{r['dt_s']:g}")
    parts = [f"{integ} at {head}{', '.join(vals)}" + ("" if "tol" in head else " s") for (integ, head), vals in groups.items()]
    return "; ".join(parts) or "none"


def _presets(res: StudyResult) -> list[str]:
    return sorted({r["preset"] for r in res.rows}, key=list(PRESETS).index)


def _floor_n(res: StudyResult) -> str:
    ns = sorted({r["own_floor_n"] for r in res.rows})
    return "/".join(str(n) for n in ns) or "0"


def _cheapest_lines(res: StudyResult) -> list[str]:
    """The cheapest setting of each integrator that reaches its preset's target agreement."""
    lines = [
        "",
        "## Cheapest setting of each integrator at the target agreement",
        "",
        f"Target: agreement ≥ 0.97 on `seed`, ≥ 0.93 on `physical`; ratio: CPU time over {BASELINE_INTEGRATOR}'s "
        "cheapest such setting (same run of the study).",
        "",
        "| preset | integrator | setting | CPU ms/IC | agreement | own floor (flips) | ratio to "
        f"{BASELINE_INTEGRATOR} |",
        "|---|---|---|---|---|---|---|",
    ]
    for preset in _presets(res):
        for c in cheapest_at_target(res.rows, preset):
            r = c["run"]
            if r is None:
                lines.append(f"| {preset} | {c['integrator']} | none reaches {c['target']:g} | — | — | — | — |")
                continue
            lines.append(
                f"| {preset} | {c['integrator']} | {setting(r)} | {r['cpu_ms_per_ic']:.3g} | {r['outcome_agreement']:.3f} | "
                f"{r['own_floor_flips']}/{r['own_floor_n']} | {_fmt(c['ratio'], '.2f')} |"
            )
    return lines


def _budget_points(costs, seed_cost):
    pts = []
    if np.isfinite(seed_cost):
        pts = [seed_cost * f for f in (1.0, 10.0, 100.0)]
    elif costs:
        pts = [costs[0], costs[len(costs) // 2], costs[-1]]
    return pts


def plot_study(res: StudyResult, path) -> None:
    """Outcome agreement and first-impact error against CPU time per IC, one line per integrator."""
    import matplotlib  # matplotlib is slow to import: only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = [p for p in PRESETS if any(r["preset"] == p for r in res.rows)]
    fig, axes = plt.subplots(len(presets), 2, figsize=(12, 4.6 * len(presets)), squeeze=False)
    for row, preset in enumerate(presets):
        ref = next(x for x in res.references if x["preset"] == preset)
        ax, bx = axes[row]
        for integ in INTEGRATORS:
            mine = sorted((r for r in res.rows if r["preset"] == preset and r["integrator"] == integ),
                          key=lambda r: r["cpu_ms_per_ic"])
            if not mine:
                continue
            graded = [r for r in mine if grows(r)]
            rr = [r for r in mine if not grows(r)]
            c = [r["cpu_ms_per_ic"] for r in rr]
            ax.plot(c, [r["outcome_agreement"] for r in rr], "o-", color=color(integ), label=integ)
            if graded:
                ax.plot([r["cpu_ms_per_ic"] for r in graded], [r["outcome_agreement"] for r in graded], "*",
                        ms=9, color=color(integ), label=f"{integ}, tol growing over the throw")
            for r in mine:
                lab = f"{r['tol']:.0e}" if np.isfinite(r.get("tol", float("nan"))) else f"{r['dt_s']:g}"
                if grows(r):
                    lab += f"↑{r['tol_growth']:g}/s"
                ax.annotate(lab, (r["cpu_ms_per_ic"], r["outcome_agreement"]), fontsize=6,
                            xytext=(2, 2), textcoords="offset points", color=color(integ))
            e = np.array([r["first_impact_error_cm"] for r in rr], float)
            e = np.where(np.isfinite(e), e, np.nan)
            bx.plot(c, e, "o-", color=color(integ), label=integ)
        for rel, ls in zip(PERTURBATIONS, (":", "--", "-.")):
            ax.axhline(ref[f"chaos_floor_{rel:.0e}"], color="k", ls=ls, lw=1, label=f"chaos floor δ={rel:g}")
        ax.axhline(1 / 6, color="grey", lw=0.8, ls="-", alpha=0.5, label="chance (1/6)")
        for f in (1.0, 10.0):
            if np.isfinite(res.seed_cost_ms):
                ax.axvline(f * res.seed_cost_ms, color="grey", lw=0.8, ls=":")
                bx.axvline(f * res.seed_cost_ms, color="grey", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("CPU time per throw (ms, one thread)")
        ax.set_ylabel("outcome agreement with the reference")
        ax.set_title(f"{preset}: outcome agreement (labels: dt in s, or tol; dotted: seed cost, 10×)")
        ax.legend(fontsize=7, loc="upper left")
        bx.set_xscale("log")
        chk = ref["check_first_impact_error_cm"]
        if np.isfinite(chk) and chk > 0:
            bx.axhline(chk, color="k", ls="--", lw=1, label="reference vs dt/2")
        errs = [r["first_impact_error_cm"] for r in res.rows if r["preset"] == preset]
        if any(np.isfinite(e) and e > 0 for e in errs):
            bx.set_yscale("log")
        bx.set_xlabel("CPU time per throw (ms, one thread)")
        bx.set_ylabel("node-position error 20 ms after first contact (cm)")
        bx.set_title(f"{preset}: first-impact trajectory error (median)")
        bx.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    write_figure(fig, path, dpi=110)


def write_study(res: StudyResult, out_dir, command: str) -> dict:
    """Write study.csv, orders.csv, reference.csv, work_precision.png and summary.md into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "csv": out / "study.csv",
        "orders": out / "orders.csv",
        "reference": out / "reference.csv",
        "png": out / "work_precision.png",
        "summary": out / "summary.md",
    }
    for key, table in (("csv", res.table()), ("orders", pd.DataFrame(res.orders)),
                       ("reference", pd.DataFrame(res.references))):
        with written(paths[key], "table") as tmp:
            table.to_csv(tmp, index=False)
    if res.preset_comparison:
        paths["presets"] = write_text(out / "presets.json", json.dumps(res.preset_comparison, indent=1) + "\n",
                                      "results file")
    plot_study(res, paths["png"])
    write_text(paths["summary"], summary_markdown(res, command), "summary")
    return paths
