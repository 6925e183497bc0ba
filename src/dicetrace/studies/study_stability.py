"""Study stability: the map of the integrators' stable steps.

Computation and rendering (``dicetrace analyze stability``): :func:`stability_map` finds, for each preset × integrator × stiffness k, the
largest dt (log bisection) at which every IC of an extreme corpus (violent
drops, spins, grazing throws) ends without a blow-up or a non-finite state,
and compares it with the linear bound ω·dt < ``IntegratorSpec.stability_bound``
(per sub-step for the sub-stepping schemes) and with ``dt = "auto"``.
:func:`write_stability` writes ``stability.csv``, ``stability.png`` and
``stability.md``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from dicetrace.ics import SEED_SLICE
from dicetrace.params import INTEGRATORS, Config, Numerics, convert_l, get_preset
from dicetrace.stepsize import auto_dt, impact_speed_cm_s
from dicetrace.status import Status
from dicetrace.studies.outputs import write_figure, write_text, written
from dicetrace.studies.study_accuracy import PRESETS, check_integrators
from dicetrace.studies.study_accuracy_grids import color
from dicetrace.studies.text import fmt

K_VALUES = (5e5, 5e5 * 10**0.5, 5e6, 5e6 * 10**0.5, 5e7)
QUICK_K_VALUES = (5e5, 5e7)
#: Time cap of the stability runs, s (covers the first impacts, where the speeds peak).
STABILITY_T_MAX_S = 0.5
DT_SEARCH = (1e-6, 1.6e-2)
BISECTIONS = 7


def extreme_corpus(seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """The extreme ICs (program convention) and their labels.

    |U| up to 2000 cm/s, |L| up to 5000 node-mass·cm²/s; near-vertical
    drops (flat and tilted), pure spins, grazing throws, random violent
    throws and a few ordinary seed-slice throws.
    """
    rng = np.random.default_rng([seed, 4242])
    ics, labels = [], []

    def add(u, l, label):
        ics.append(np.r_[np.asarray(u, float), np.asarray(l, float)])
        labels.append(label)

    for v in (100.0, 1000.0, 2000.0):
        add((0, 0, -v), (0, 0, 0), f"vertical drop {v:g} cm/s, flat")
    add((0, 0, -2000.0), (30.0, -20.0, 0), "vertical drop 2000 cm/s, tilted")
    for axis, name in (((0, 0, 1), "z"), ((1, 0, 0), "x"), ((1, 1, 1), "diagonal")):
        a = np.asarray(axis, float)
        add((0, 0, 0), 5000.0 * a / np.linalg.norm(a), f"pure spin |L|=5000 about {name}")
    add((2000.0, 0, 0), (0, 0, 0), "grazing 2000 cm/s")
    add((1414.0, 1414.0, -5.0), (0, 0, 500.0), "grazing 2000 cm/s, yawing")
    add((2000.0, 0, 0), (0, 5000.0, 0), "grazing 2000 cm/s, topspin 5000")
    for i in range(4):
        u = rng.normal(size=3)
        u = 2000.0 * u / np.linalg.norm(u)
        l = rng.normal(size=3)
        l = 5000.0 * l / np.linalg.norm(l)
        add(u, l, f"violent random throw {i + 1}")
    for x, y in ((1.65, 3.9), (5.0, 5.0), (50.0, 50.0)):
        add(*np.split(SEED_SLICE.ics([x, y]), 2), f"seed slice ({x:g}, {y:g})")
    return np.array(ics), labels


def corpus_stable(ics_preset: np.ndarray, cfg: Config) -> tuple[bool, int, int]:
    """(all stable, index of the first unstable IC or -1, time caps); stops at the first failure."""
    from dicetrace.simulate import simulate  # lazy: keeps `dicetrace --help` fast (imports numba)

    caps = 0
    for i, ic in enumerate(ics_preset):
        r = simulate(ic, config=cfg)
        if r.status.failed:
            return False, i, caps
        caps += r.status is Status.TIME_CAP
    return True, -1, caps


def largest_stable_dt(ics, preset_obj, integrator, *, bisections=BISECTIONS, lo_hi=DT_SEARCH):
    """Largest dt in [lo, hi] (log bisection) at which every corpus IC is stable.

    Returns (dt_stable or 0.0 if even ``lo`` fails, dt_unstable or inf,
    index of the IC that failed at dt_unstable).  Assumes stability is
    monotone in dt (checked only at the probed steps).
    """
    lo, hi = lo_hi

    def cfg(dt):
        return Config(preset=preset_obj, numerics=Numerics(integrator=integrator, dt_s=dt, t_max_s=STABILITY_T_MAX_S))

    ok_hi, fail_hi, _ = corpus_stable(ics, cfg(hi))
    if ok_hi:
        return hi, math.inf, -1
    ok_lo, fail_lo, _ = corpus_stable(ics, cfg(lo))
    if not ok_lo:
        return 0.0, lo, fail_lo
    fail = fail_hi
    for _ in range(bisections):
        mid = math.sqrt(lo * hi)
        ok, f, _ = corpus_stable(ics, cfg(mid))
        if ok:
            lo = mid
        else:
            hi, fail = mid, f
    return lo, hi, fail


def stability_map(
    *,
    quick: bool = False,
    presets=PRESETS,
    integrators=None,
    k_values=None,
    seed: int = 0,
    bisections: int | None = None,
    progress=None,
) -> list[dict]:
    """Largest stable dt per preset × integrator × k over the extreme corpus (see the module docstring)."""
    say = progress or (lambda msg: None)
    integrators = check_integrators(integrators)
    k_values = tuple(k_values or (QUICK_K_VALUES if quick else K_VALUES))
    ics_prog, labels = extreme_corpus(seed)
    if quick:
        keep = [0, 2, 4, 7, 10]
        ics_prog, labels = ics_prog[keep], [labels[i] for i in keep]
    nb = int(bisections if bisections is not None else (3 if quick else BISECTIONS))
    rows = []
    for preset in presets:
        base = get_preset(preset)
        ics = convert_l(ics_prog, "program", base.l_convention)
        v_imp = impact_speed_cm_s(ics_prog, base)
        for integ in integrators:
            for k in k_values:
                p = base.with_(k=float(k))
                say(f"[{preset}] {integ} k={k:.3g}")
                dt_ok, dt_bad, fail = largest_stable_dt(ics, p, integ, bisections=nb)
                spec = INTEGRATORS[integ]
                bound = spec.stability_bound * (Numerics.substeps if spec.substepped and not spec.adaptive else 1)
                try:
                    adt = auto_dt(p, integ, v_impact_cm_s=v_imp, t_max_s=STABILITY_T_MAX_S)
                    cfg = Config(preset=p, numerics=Numerics(integrator=integ, dt_s=adt, t_max_s=STABILITY_T_MAX_S))
                    auto_ok = corpus_stable(ics, cfg)[0]
                    refusal = ""
                except ValueError as e:
                    adt, auto_ok, refusal = float("nan"), None, str(e)
                rows.append(
                    {
                        "preset": preset,
                        "integrator": integ,
                        "k": float(k),
                        "omega_rad_s": math.sqrt(k),
                        "dt_stable_s": dt_ok,
                        "dt_unstable_s": dt_bad,
                        "omega_dt_stable": math.sqrt(k) * dt_ok,
                        "linear_bound_omega_dt": bound,
                        "linear_bound_dt_s": bound / math.sqrt(k) if bound > 0 else 0.0,
                        "first_failing_ic": labels[fail] if fail >= 0 else "",
                        "auto_dt_s": adt,
                        "auto_dt_stable": auto_ok,
                        "auto_dt_refusal": refusal,
                        "impact_speed_cm_s": v_imp,
                        "n_corpus": len(ics),
                        "t_max_s": STABILITY_T_MAX_S,
                    }
                )
    return rows


STABILITY_COLUMNS = (
    "preset",
    "integrator",
    "k",
    "omega_rad_s",
    "dt_stable_s",
    "dt_unstable_s",
    "omega_dt_stable",
    "linear_bound_omega_dt",
    "linear_bound_dt_s",
    "first_failing_ic",
    "auto_dt_s",
    "auto_dt_stable",
    "auto_dt_refusal",
    "impact_speed_cm_s",
    "n_corpus",
    "t_max_s",
)


def stability_markdown(rows: list[dict], command: str) -> str:
    ics, labels = extreme_corpus()
    lines = [
        "# Stability map",
        "",
        f"Command: `{command}`",
        "",
        f"Largest dt (log bisection in [{DT_SEARCH[0]:g}, {DT_SEARCH[1]:g}] s) at which every IC of the extreme corpus "
        f"ends without a blow-up or a non-finite state within {STABILITY_T_MAX_S:g} s (the first impacts, where the "
        "speeds peak), against the linear bound on the undamped spring (ω = √k per unit mass; contact-substep: "
        "RK4's bound per sub-step, 8 sub-steps; contact-adaptive: RK4's bound on a sub-step as long as dt, though its "
        "error control shortens them), and the step `dt = \"auto\"` picks.",
        "",
        "| preset | integrator | k | ω·dt stable | stable dt (s) | unstable dt (s) | linear bound ω·dt | auto dt (s) | auto stable | first failing IC |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        auto = fmt(r["auto_dt_s"], ".3g", missing="—") if not r["auto_dt_refusal"] else "refused"
        lines.append(
            f"| {r['preset']} | {r['integrator']} | {r['k']:.3g} | {r['omega_dt_stable']:.3g} | {r['dt_stable_s']:.3g} | "
            f"{fmt(r['dt_unstable_s'], '.3g', missing='—')} | {r['linear_bound_omega_dt']:.3g} | {auto} | "
            f"{'—' if r['auto_dt_stable'] is None else ('yes' if r['auto_dt_stable'] else 'NO')} | {r['first_failing_ic']} |"
        )
    lines += ["", "Corpus (program convention):", ""]
    for lab, ic in zip(labels, ics):
        lines.append(f"- {lab}: U = ({ic[0]:g}, {ic[1]:g}, {ic[2]:g}) cm/s, L = ({ic[3]:g}, {ic[4]:g}, {ic[5]:g})")
    return "\n".join(lines) + "\n"


def plot_stability(rows: list[dict], path) -> None:
    import matplotlib  # matplotlib is slow to import: only when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = [p for p in PRESETS if any(r["preset"] == p for r in rows)]
    fig, axes = plt.subplots(1, len(presets), figsize=(6.5 * len(presets), 4.6), squeeze=False)
    for ax, preset in zip(axes[0], presets):
        for integ in INTEGRATORS:
            rr = [r for r in rows if r["preset"] == preset and r["integrator"] == integ]
            if not rr:
                continue
            k = [r["k"] for r in rr]
            ax.plot(k, [max(r["dt_stable_s"], 1e-7) for r in rr], "o-", color=color(integ), label=f"{integ}: largest stable dt")
            if rr[0]["linear_bound_dt_s"] > 0:
                ax.plot(k, [r["linear_bound_dt_s"] for r in rr], ":", color=color(integ), label=f"{integ}: linear bound")
            ax.plot(k, [r["auto_dt_s"] for r in rr], "x", color=color(integ), ms=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("ground stiffness k (1/s², per unit mass)")
        ax.set_ylabel("dt (s)")
        ax.set_title(f"{preset}: stable dt over the extreme corpus (x: dt auto)")
        ax.legend(fontsize=6)
    fig.tight_layout()
    write_figure(fig, path, dpi=110)


def write_stability(rows: list[dict], out_dir, command: str) -> dict:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out / "stability.csv", "png": out / "stability.png", "summary": out / "stability.md"}
    with written(paths["csv"], "table") as tmp:
        pd.DataFrame(rows, columns=list(STABILITY_COLUMNS)).to_csv(tmp, index=False)
    plot_stability(rows, paths["png"])
    write_text(paths["summary"], stability_markdown(rows, command), "summary")
    return paths
