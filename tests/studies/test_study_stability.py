"""Blow-ups are reported as such, never as outcomes; the stability map and ``dt = "auto"``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.params import INTEGRATORS, get_preset, make_config
from dicetrace.stepsize import auto_dt, impact_speed_cm_s
from dicetrace.simulate import simulate, simulate_batch
from dicetrace.status import LABELS

ALL = tuple(INTEGRATORS)


@pytest.mark.parametrize("preset", ["seed", "physical"])
def test_forward_euler_blows_up_on_the_ground(preset):
    """Forward Euler at the program's dt = 1e-3 s (ω·dt ≈ 0.71 on the spring) gains
    √(1 + ω²dt²) ≈ 1.22 in amplitude per step: a die pushed into the ground at
    30 cm/s is a blow-up within a few steps, with no outcome."""
    cfg = make_config(preset, integrator="forward-euler", dt_s=1e-3, z0_cm=1.0)
    r = simulate([0.0, 0.0, -30.0, 0.0, 0.0, 0.0], config=cfg)
    assert r.status == "blow_up"
    assert r.outcome == -1 and not r.settled
    assert r.steps < 20


@pytest.mark.parametrize("integ", ["semi-implicit-euler", "verlet", "rk4", "contact-substep"])
def test_stable_schemes_settle_the_same_drop(integ):
    cfg = make_config("seed", integrator=integ, dt_s=1e-3, z0_cm=1.0)
    r = simulate([0.0, 0.0, -30.0, 0.0, 0.0, 0.0], config=cfg)
    assert r.status == "settled" and r.outcome == 4  # face 4 up: it started that way


def test_blow_up_is_never_an_outcome_in_a_batch():
    """A batch mixing stable and unstable steps: every unsettled row has outcome -1."""
    from dicetrace.ics import seed_slice

    ics = seed_slice(np.linspace(0.1, 9, 12), np.linspace(0.2, 8, 12))
    for integ, dt in (("forward-euler", 1e-3), ("semi-implicit-euler", 3e-3), ("rk4", 5e-3)):
        r = simulate_batch(ics, integrator=integ, dt_s=dt, t_max_s=5.0)
        status = r.status
        assert set(status) <= set(LABELS)
        assert np.all(r.outcome[status != "settled"] == -1)
        assert np.all((r.outcome[status == "settled"] >= 0) & (r.outcome[status == "settled"] <= 6))


@pytest.mark.parametrize("integ", ALL)
def test_every_run_ends_with_a_status(integ):
    r = simulate([40.0, -25.0, 10.0, 300.0, -200.0, 150.0], integrator=integ, dt_s=2e-3, t_max_s=3.0)
    assert r.status in ("settled", "time_cap", "non_finite", "blow_up")
    assert (r.outcome >= 0) == (r.status == "settled")


# -- dt auto ---------------------------------------------------------------------------------------


def test_auto_dt_respects_the_linear_bound():
    p = get_preset("seed")
    for k in (5e5, 5e6, 5e7):
        q = p.with_(k=k)
        for integ in ("semi-implicit-euler", "verlet", "rk4"):
            dt = auto_dt(q, integ, v_impact_cm_s=0.0)
            assert math.sqrt(k) * dt <= 0.5 * INTEGRATORS[integ].stability_bound * (1 + 1e-12) or dt == 1e-3


def test_auto_dt_at_high_stiffness_gives_a_correct_answer():
    """k = 5e7 (100× the seed's): dt auto gives a run that settles, rk4 and the contact schemes the outcome
    of a much finer contact-substep reference, the contact schemes its settle time too.  The error-controlled ones get 1 ms whatever
    k (ω·dt = 7, beyond every explicit bound): their error control keeps them stable and converged."""
    from dicetrace.ics import seed_slice

    ic = seed_slice(0.3, 0.7)
    v = impact_speed_cm_s(ic, get_preset("seed"))
    ref = simulate(ic, config=make_config("seed", integrator="contact-substep", dt_s=2.5e-5, k=5e7))
    assert ref.status == "settled"
    t_ref = ref.steps * 2.5e-5
    for integ in ("semi-implicit-euler", "rk4", "contact-substep", "contact-adaptive", "contact-tsit5"):
        cfg = make_config("seed", integrator=integ, dt_s="auto", k=5e7, v_impact_cm_s=v)
        dt = cfg.numerics.dt_s
        if INTEGRATORS[integ].adaptive:
            assert dt == 1e-3
        else:
            assert math.sqrt(5e7) * dt < INTEGRATORS[integ].stability_bound * (8 if integ == "contact-substep" else 1)
        r = simulate(ic, config=cfg)
        assert r.status == "settled", (integ, dt)
        if integ != "semi-implicit-euler":  # order 1: stable at its dt auto, not converged there
            assert r.outcome == ref.outcome, (integ, dt, r.outcome, ref.outcome)
        if integ.startswith("contact-"):  # the settle time too (rk4 at ω·dt = 0.7 ends 70 ms early)
            assert abs(r.steps * dt - t_ref) <= 5e-3, (integ, r.steps * dt, t_ref)


def test_auto_dt_refuses_clearly():
    with pytest.raises(ValueError, match=r"^dt auto: forward-euler needs dt <= .*budget"):
        make_config("seed", integrator="forward-euler", dt_s="auto", k=5e7)
    with pytest.raises(ValueError, match="'auto'"):
        make_config("seed", dt_s="fast")


def test_auto_dt_default_integrator_and_message_is_one_line():
    cfg = make_config("seed", dt_s="auto")
    assert 0 < cfg.numerics.dt_s <= 1e-3
    try:
        make_config("physical", integrator="rk4", dt_s="auto", k=1e12)
    except ValueError as e:
        assert "\n" not in str(e)
    else:  # pragma: no cover
        raise AssertionError("k = 1e12 with rk4 should be refused")


# -- the stability map -------------------------------------------------------------------------------


def test_corpus_is_extreme():
    from dicetrace.studies.study_stability import extreme_corpus

    ics, labels = extreme_corpus()
    assert len(ics) == len(labels) >= 12
    assert np.isclose(np.linalg.norm(ics[:, :3], axis=1).max(), 2000.0, rtol=1e-3)
    assert np.isclose(np.linalg.norm(ics[:, 3:], axis=1).max(), 5000.0)
    assert any("spin" in s for s in labels) and any("grazing" in s for s in labels) and any("drop" in s for s in labels)


def test_stability_map_small():
    """Semi-implicit Euler at the seed's k: stable below its linear bound 2/ω, and dt auto is stable."""
    from dicetrace.studies.study_stability import stability_map

    rows = stability_map(quick=True, presets=("seed",), integrators=("semi-implicit-euler",), k_values=(5e5,), bisections=4)
    (r,) = rows
    assert 0 < r["dt_stable_s"] < r["dt_unstable_s"]
    assert r["omega_dt_stable"] < 2.0  # never beyond the linear bound ω·dt < 2
    assert r["auto_dt_stable"] is True and r["auto_dt_s"] <= r["dt_stable_s"]


@pytest.mark.slow
@pytest.mark.long
def test_stability_cli_rejects_bad_input(tmp_path):
    import subprocess
    import sys

    for args in (["--k", "0"], ["--integrator", "euler"], ["--presets", "nope"]):
        res = subprocess.run(
            [sys.executable, "-m", "dicetrace.cli", "stability", *args, "--out", str(tmp_path)],
            capture_output=True, text=True, timeout=300,
        )
        assert res.returncode == 2, res.stderr
        assert res.stderr.startswith("dicetrace: error:") and res.stderr.count("\n") == 1
