"""The ground law in a physicist's terms (dicetrace.materials): restitution against the exact equation, the impact
ODE and the simulator; its inverse; friction; and the table of docs/model.md "Materials: restitution and friction"."""

from __future__ import annotations

import math
import re
from decimal import Decimal, getcontext
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

from dicetrace import materials as m
from dicetrace.params import get_preset

PHYS = get_preset("physical")
DOCS = Path(__file__).resolve().parents[1] / "docs" / "model.md"


def _exact_e(a: float) -> float:
    """e = b/a from a − ln(1 + a) = −b − ln(1 − b), bisected in 50-digit decimals (no Lambert W, no series)."""
    getcontext().prec = 50
    A = Decimal(repr(a))
    rhs = A - (1 + A).ln()
    lo, hi = Decimal(0), Decimal(1)
    for _ in range(200):
        mid = (lo + hi) / 2
        if -mid - (1 - mid).ln() < rhs:
            lo = mid
        else:
            hi = mid
    return float((lo + hi) / 2 / A)


@pytest.mark.parametrize("a", [1e-8, 1e-4, 0.01, 0.0499, 0.05, 0.0501, 0.3, 1.0, 3.0, 30.0, 300.0])
def test_restitution_matches_the_exact_equation(a):
    assert m.restitution(a, 1.0) == pytest.approx(_exact_e(a), rel=1e-13)
    # γ and v enter only through their product
    assert m.restitution(a / 0.005, 0.005) == pytest.approx(_exact_e(a), rel=1e-13)


@pytest.mark.parametrize("k, n_contact, mass", [(5e5, 1, 1.0), (1e3, 1, 1.0), (1e8, 1, 1.0), (5e5, 4, 8.0),
                                                (5e5, 1, 8.0), (2e4, 2, 3.0)])
def test_restitution_matches_solve_ivp_for_any_stiffness_and_mass(k, n_contact, mass):
    v = np.array([1.0, 10.0, 100.0, 165.65, 1000.0, 5000.0])
    closed = m.restitution(v, 0.005)
    ode = np.array([m.impact(x, k, 0.005, n_contact=n_contact, mass=mass).e for x in v])
    np.testing.assert_allclose(ode, closed, rtol=1e-8)


def test_restitution_limits():
    assert m.restitution(100.0, 0.0) == 1.0
    a = 1e-6
    assert (1 - m.restitution(a, 1.0)) / a == pytest.approx(2 / 3, rel=1e-5)
    for a in (50.0, 1e3, 1e6):  # the exit speed saturates at 1/γ
        assert a * m.restitution(a, 1.0) == pytest.approx(1.0, rel=1e-10)
    e = m.restitution(np.geomspace(1e-3, 1e3, 200), 1.0)
    assert np.all(np.diff(e) < 0) and np.all((e > 0) & (e < 1))


def test_the_clamp_never_acts_on_a_normal_impact():
    for g in (0.0, -980.0):
        for v in (0.5, 10.0, 165.65, 2000.0):
            clamped = m.impact(v, PHYS.k, PHYS.gamma, g=g, clamp=True)
            signed = m.impact(v, PHYS.k, PHYS.gamma, g=g, clamp=False)
            assert clamped == signed
            assert clamped.v_out < 1.0 / PHYS.gamma


def test_undamped_impact_is_a_harmonic_half_swing():
    k, v, g = 5e5, 50.0, -980.0
    w = math.sqrt(k)
    free = m.impact(v, k, 0.0)
    assert free.e == pytest.approx(1.0, rel=1e-10)
    assert free.contact_time == pytest.approx(math.pi / w, rel=1e-10)
    assert free.max_depth == pytest.approx(v / w, rel=1e-10)
    # with gravity: d = d_s + A·sin(ωt − φ), d_s = |g|/ω², A = √(d_s² + (v/ω)²), sin φ = d_s/A
    ds = -g / k
    amp = math.hypot(ds, v / w)
    heavy = m.impact(v, k, 0.0, g=g)
    assert heavy.e == pytest.approx(1.0, rel=1e-10)
    assert heavy.contact_time == pytest.approx((math.pi + 2 * math.asin(ds / amp)) / w, rel=1e-10)
    assert heavy.max_depth == pytest.approx(ds + amp, rel=1e-10)
    # the die's flat drop: four nodes, eight node masses, the stiffness k/2
    flat = m.impact(v, k, 0.0, n_contact=4, mass=8.0)
    assert flat.contact_time == pytest.approx(math.sqrt(2) * math.pi / w, rel=1e-10)


def test_gravity_lowers_restitution_and_a_slow_body_stays_down():
    for v in (1.0, 10.0, 165.65):
        free = m.restitution(v, PHYS.gamma)
        point = m.impact(v, PHYS.k, PHYS.gamma, g=PHYS.g).e
        flat = m.impact(v, PHYS.k, PHYS.gamma, g=PHYS.g, n_contact=4, mass=8.0).e
        assert flat < point < free
    stuck = m.impact(0.01, PHYS.k, PHYS.gamma, g=PHYS.g)
    assert stuck.e == 0.0 and not stuck.separated and math.isnan(stuck.contact_time)


@pytest.mark.parametrize("e", [0.05, 0.3, 0.5, 0.6312, 0.9, 0.999])
def test_gamma_for_restitution_inverts(e):
    v = 165.65
    gam = m.gamma_for_restitution(e, v)
    assert m.restitution(v, gam) == pytest.approx(e, rel=1e-12)
    # k plays no part without gravity
    assert m.gamma_for_restitution(e, v, 1e3) == gam
    gam_flat = m.gamma_for_restitution(e, v, PHYS.k, g=PHYS.g, n_contact=4, mass=8.0)
    assert m.impact(v, PHYS.k, gam_flat, g=PHYS.g, n_contact=4, mass=8.0).e == pytest.approx(e, rel=1e-9)
    assert gam_flat < gam  # gravity already takes some of the bounce


def test_gamma_for_restitution_of_the_physical_preset():
    assert m.gamma_for_restitution(m.restitution(100.0, PHYS.gamma), 100.0) == pytest.approx(PHYS.gamma, rel=1e-12)
    assert m.gamma_for_restitution(1.0, 100.0) == 0.0
    assert m.gamma_for_restitution(1.0, 100.0, PHYS.k, g=PHYS.g) == 0.0


@pytest.mark.parametrize("call, word", [
    (lambda: m.gamma_for_restitution(0.0, 100.0), "restitution"),
    (lambda: m.gamma_for_restitution(1.5, 100.0), "restitution"),
    (lambda: m.gamma_for_restitution(float("nan"), 100.0), "restitution"),
    (lambda: m.gamma_for_restitution(0.5, -1.0), "v_ref"),
    (lambda: m.gamma_for_restitution(0.5, 100.0, g=-980.0), "stiffness k"),
    (lambda: m.restitution(-1.0, 0.005), "impact speed"),
    (lambda: m.restitution(1.0, -0.005), "gamma"),
    (lambda: m.impact(1.0, 5e5, 0.005, g=980.0), "g must"),
    (lambda: m.impact(1.0, 5e5, 0.005, n_contact=9), "n_contact"),
    (lambda: m.friction_coefficient_at(1.0, 1.2, 0.0), "v_reg"),
])
def test_bad_input_is_refused_in_one_line_naming_it(call, word):
    with pytest.raises(ValueError) as err:
        call()
    assert word in str(err.value) and "\n" not in str(err.value)


def test_drop_speed():
    assert m.drop_speed(14.0) == pytest.approx(math.sqrt(2 * 980 * 14))
    assert m.drop_speed(0.0) == 0.0


@pytest.mark.slow
def test_the_simulators_flat_drop_bounces_as_derived():
    """`physical` dropped flat from its start: the first bounce's e measured on the trajectory against impact()."""
    from dicetrace.simulate import Record, simulate

    roll = simulate(np.zeros(6), preset="physical", record=Record(states=True, energy=False))
    z = roll.trace.cm_pos[:, 2] - PHYS.half_side_cm  # height of the bottom face
    vz = roll.trace.cm_vel[:, 2]
    assert np.all(roll.trace.cm_pos[:, :2] == 0) and np.all(roll.trace.L == 0)  # it never turns or slides
    touching = z <= 0
    first = int(np.argmax(touching))
    after = first + int(np.argmax(~touching[first:]))
    g = -PHYS.g
    # speeds at the ground from free-flight samples on either side of the contact (energy, exact in free flight)
    v_in = math.sqrt(vz[first - 1] ** 2 + 2 * g * z[first - 1])
    v_out = math.sqrt(vz[after] ** 2 + 2 * g * z[after])
    assert v_in == pytest.approx(float(m.drop_speed(PHYS.z0_cm - PHYS.half_side_cm)), rel=1e-9)
    e_sim = v_out / v_in
    derived = m.impact(v_in, PHYS.k, PHYS.gamma, g=PHYS.g, n_contact=4, mass=8.0).e
    assert e_sim == pytest.approx(derived, rel=1e-6)
    assert abs(e_sim - m.restitution(v_in, PHYS.gamma)) > 5e-3  # gravity's share is resolved, not hidden
    assert round(e_sim, 5) == 0.63125  # docs/model.md quotes it


def test_friction_law():
    mu, vr = PHYS.mu, PHYS.v_reg_cm_s
    assert m.friction_coefficient_at(0.0, mu, vr) == 0.0
    assert m.friction_coefficient_at(5 * vr, mu, vr) >= 0.98 * mu
    assert m.friction_coefficient_at(1e6, mu, vr) == pytest.approx(mu, rel=1e-9)
    assert m.friction_coefficient_at(1e-3, mu, vr) == pytest.approx(mu * 1e-3 / vr, rel=1e-6)
    tau = m.friction_relaxation_time(mu, vr, PHYS.g)
    assert tau == pytest.approx(vr / (mu * 980.0))
    # a slow slide on a face under the full law: du/dt = −μ|g|·u/√(u² + v_reg²) decays as e^(−t/τ)
    u0 = 1e-3 * vr
    sol = integrate.solve_ivp(lambda t, u: -mu * 980.0 * u / np.sqrt(u * u + vr * vr), (0, tau), [u0],
                              rtol=1e-12, atol=1e-20)
    assert sol.y[0, -1] / u0 == pytest.approx(math.exp(-1), rel=1e-5)


def test_literature_values_carry_sources_and_the_presets_mu_is_above_them():
    for entry in m.LITERATURE["friction_steel_on_wood"]:
        assert entry["source"] and entry["kind"] in ("static", "kinetic")
        top = max(np.atleast_1d(entry["value"]))
        assert 0 < top < PHYS.mu  # docs/model.md: "The presets' μ = 1.2 is above every value in this table."
    assert m.LITERATURE["restitution_steel_on_wood"] is None and m.LITERATURE["hand_throw"] is None


def _docs_table() -> list[list[str]]:
    text = DOCS.read_text()
    section = text[text.index("## 13. Materials: restitution and friction"):]
    head = section.index("| impact speed (cm/s)")
    rows = []
    for line in section[head:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows


def test_the_docs_restitution_table_is_what_the_functions_give():
    rows = _docs_table()
    assert len(rows) == 6
    for row in rows:
        v = float(row[0])
        free = m.restitution(v, PHYS.gamma)
        point = m.impact(v, PHYS.k, PHYS.gamma, g=PHYS.g)
        flat = m.impact(v, PHYS.k, PHYS.gamma, g=PHYS.g, n_contact=4, mass=8.0)
        got = [PHYS.gamma * v, free, point.e, flat.e, point.contact_time * 1e3, flat.contact_time * 1e3,
               flat.max_depth * 10]
        for cell, value in zip(row[1:], got):
            decimals = len(cell.split(".")[1]) if "." in cell else 0
            assert float(cell) == pytest.approx(value, abs=0.51 * 10**-decimals), (row, cell, value)
    # and the numbers quoted in the text around it
    text = DOCS.read_text()
    assert re.search(r"sinks 2\.7 mm", text) and round(flat.max_depth * 10, 1) == 10.1  # the 1000 cm/s row
    flat_drop = m.impact(float(m.drop_speed(14.0)), PHYS.k, PHYS.gamma, g=PHYS.g, n_contact=4, mass=8.0)
    assert round(flat_drop.max_depth * 10, 1) == 2.7 and round(flat_drop.contact_time * 1e3, 1) == 6.5
    assert round(m.restitution(float(m.drop_speed(14.0)), PHYS.gamma), 4) == 0.6398
    assert round(m.friction_relaxation_time(PHYS.mu, PHYS.v_reg_cm_s, PHYS.g) * 1e3, 1) == 8.5


@pytest.mark.slow
@pytest.mark.parametrize("e", [0.3, 0.8])
def test_a_presets_restitution_is_the_flat_drops_at_its_reference_speed(e):
    """``restitution=e`` sets γ; the simulator's flat drop at the reference speed (100 cm/s) then bounces with e,
    measured on its trajectory (as above) to 1e-6."""
    from dicetrace.params import RESTITUTION_SPEED_CM_S, make_config
    from dicetrace.simulate import Record, simulate

    v = RESTITUTION_SPEED_CM_S
    cfg = make_config("physical", restitution=e, z0_cm=PHYS.half_side_cm + v * v / (2 * -PHYS.g))
    assert cfg.preset.gamma == pytest.approx(m.gamma_for_restitution(e, v, PHYS.k, g=PHYS.g, n_contact=4, mass=8.0))
    roll = simulate(np.zeros(6), config=cfg, record=Record(states=True, energy=False))
    z = roll.trace.cm_pos[:, 2] - PHYS.half_side_cm
    vz = roll.trace.cm_vel[:, 2]
    touching = z <= 0
    first = int(np.argmax(touching))
    after = first + int(np.argmax(~touching[first:]))
    v_in = math.sqrt(vz[first - 1] ** 2 + 2 * -PHYS.g * z[first - 1])
    v_out = math.sqrt(vz[after] ** 2 + 2 * -PHYS.g * z[after])
    assert v_in == pytest.approx(v, rel=1e-9)
    assert v_out / v_in == pytest.approx(e, rel=1e-6)


@pytest.mark.parametrize("changes, field", [
    (dict(restitution=0.0), "restitution"), (dict(restitution=1.5), "restitution"),
    (dict(restitution="x"), "restitution"), (dict(restitution=0.5, restitution_speed_cm_s=-1.0), "restitution_speed_cm_s"),
])
def test_a_bad_restitution_is_refused_naming_it(changes, field):
    from dicetrace.params import ConfigError, make_config

    with pytest.raises(ConfigError) as err:
        make_config("physical", **changes)
    assert err.value.fields == (field,) and "\n" not in str(err.value)
