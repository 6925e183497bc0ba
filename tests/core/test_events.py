"""Exact contact events (docs/model.md §8.1): the events loops of the contact schemes.

The analytic check is a face landing flat without damping, whose contact times are known in closed form; the
invariant check reads the events at the output-step ends and must get the sampled sequence back; the unit checks
are the crossings of a height's cubic inside one sub-step, where the sub-step cuts see nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from dicetrace.core.contacts import hermite_crossings
from dicetrace.params import make_config
from dicetrace.simulate import sets_to_text, simulate, simulate_batch

#: The integrators with events loops that the suite runs: Tsit5, the `physical` default, whose dense output runs a
#: front ahead of the state (the harder case).  The schemes without dense output (contact-adaptive's RK4,
#: contact-dop853) record events through the same driver code; compiling their events kernels too would cost CI
#: ~45 s each (add them here to check them: both pass).
EVENT_INTEGRATORS = ("contact-tsit5",)


def _flat_drop_times(kp, v0: float, n: int) -> np.ndarray:
    """The first ``n`` contact-change times of the die dropped flat (face down, no spin) at v_z = −v0, γ = 0.

    Free fall to the ground; then the four lower nodes (mass 4 of 8) on springs k: the CM obeys
    y'' = g − (k/2)·y below the ground, y(0) = 0, y'(0) = v1 < 0, whose next zero is θ/ω with ω = √(k/2) and
    tan(θ/2) = −v1·ω/g; it leaves at −v1 (no damping) and flies 2|v1|/|g| to the next landing.
    """
    g, k, gap = kp.g, kp.k, kp.z0_cm - kp.half_side_cm
    t1 = (-v0 + np.sqrt(v0 * v0 + 2.0 * (-g) * gap)) / (-g)  # gap − v0·t + g·t²/2 = 0
    v1 = -v0 + g * t1
    w = np.sqrt(k / 2.0)
    contact = 2.0 * np.arctan2(-v1 * w, g) / w
    flight = 2.0 * abs(v1) / abs(g)
    times = [t1]
    while len(times) < n:
        times.append(times[-1] + (contact if len(times) % 2 == 1 else flight))
    return np.array(times)


@pytest.mark.parametrize("integrator", EVENT_INTEGRATORS)
def test_a_face_landing_flat_has_the_analytic_contact_times(integrator):
    cfg = make_config("physical", integrator=integrator, tol=1e-10, tol_growth=0.0, gamma=0.0, t_max_s=0.75)
    kp = cfg.kernel_params()
    r = simulate([0.0, 0.0, -100.0, 0.0, 0.0, 0.0], config=cfg, events=True)
    bottom = sum(1 << k for k in range(8) if cfg.initial_offsets()[k, 2] < 0)
    assert r.contact_sequence == sets_to_text([0, bottom, 0, bottom, 0])
    expected = _flat_drop_times(kp, 100.0, 4)
    assert r.contact_times[0] == 0.0
    # the landing is located on the exact free flight; the lift-off by the cubic of the node's height, to the
    # tolerance of the contact's sub-steps
    np.testing.assert_allclose(r.contact_times[1:], expected, rtol=0, atol=1e-9)
    assert np.all(np.diff(r.contact_times) > 1e-3)
    # the sampled sequence only knows the steps: the same sets, at the ends of the steps the events began in
    s = simulate([0.0, 0.0, -100.0, 0.0, 0.0, 0.0], config=cfg)
    assert s.contact_sequence == r.contact_sequence
    np.testing.assert_array_equal(r.contact_steps[1:], np.floor(expected / cfg.numerics.dt_s).astype(int) + 1)
    np.testing.assert_array_equal(s.contact_steps, r.contact_steps)
    ev = r.contact_events()
    assert list(ev["kind"]) == ["enter"] * 4 + ["leave"] * 4 + ["enter"] * 4 + ["leave"] * 4
    np.testing.assert_array_equal(ev["t_s"].to_numpy()[::4], r.contact_times[1:])


def _held_at_steps(sets, times, n_steps: int, dt: float) -> list[int]:
    """The sequence the events give when read at the end of every output step from the second on (as the loop
    samples), repeats merged."""
    ticks = np.arange(2, n_steps + 1) * dt
    held = np.asarray(sets)[np.searchsorted(times, ticks, side="right") - 1]
    out = [0]
    for v in held.tolist():
        if v != out[-1]:
            out.append(int(v))
    return out


@pytest.mark.parametrize("integrator", EVENT_INTEGRATORS)
def test_events_read_at_the_output_steps_are_the_sampled_sequence(integrator):
    """Over the first 0.4 s (bounces: many contact changes), on random throws of the converged die: the same
    steps as without events, and the sampled sequence read off the events."""
    rng = np.random.default_rng(7)
    ics = rng.normal(size=(24, 6)) * [60.0, 60.0, 20.0, 4000.0, 4000.0, 4000.0]
    opts = {} if integrator == "contact-tsit5" else {"tol": 1e-8}
    cfg = make_config("physical", integrator=integrator, t_max_s=0.4, **opts)
    dt = cfg.numerics.dt_s
    sampled = simulate_batch(ics, config=cfg)
    ev = simulate_batch(ics, config=cfg, events=True)
    np.testing.assert_array_equal(ev.status_code, sampled.status_code)
    np.testing.assert_array_equal(ev.steps, sampled.steps)
    more = 0
    for i in range(len(ics)):
        sets, times, steps = ev.contact_sets(i), ev.set_times[ev.set_offsets[i]:ev.set_offsets[i + 1]], \
            ev.set_steps[ev.set_offsets[i]:ev.set_offsets[i + 1]]
        assert times[0] == 0.0 and sets[0] == 0 and steps[0] == 0
        assert np.all(np.diff(times) > 0) and np.all(sets[1:] != sets[:-1])
        assert times[-1] < ev.steps[i] * dt
        np.testing.assert_array_equal(steps[1:], np.floor(times[1:] / dt).astype(np.int64) + 1)
        assert _held_at_steps(sets, times, int(ev.steps[i]), dt) == sampled.contact_sets(i).tolist()
        more += len(sets) - len(sampled.contact_sets(i))
    assert more > 0  # contacts shorter than a step: sampling misses them, the events do not


def test_batch_events_are_the_single_throw_events_whatever_the_buffer_and_move_nothing():
    rng = np.random.default_rng(11)
    ics = rng.normal(size=(20, 6)) * [60.0, 60.0, 20.0, 4000.0, 4000.0, 4000.0]
    cfg = make_config("physical", t_max_s=1.0)
    big = simulate_batch(ics, config=cfg, events=True)
    small = simulate_batch(ics, config=cfg, events=True, cap=2)  # every throw re-run with bigger buffers
    plain = simulate_batch(ics, config=cfg)  # strict arithmetic: recording the events moves nothing, to the last bit
    for name in ("outcome", "status_code", "steps"):
        np.testing.assert_array_equal(getattr(big, name), getattr(plain, name), err_msg=name)
    for name in ("outcome", "status_code", "steps", "set_offsets", "sets", "set_steps", "set_times"):
        np.testing.assert_array_equal(getattr(small, name), getattr(big, name), err_msg=name)
    for i in (0, 7, 19):
        r = simulate(ics[i], config=cfg, events=True)
        assert (r.steps, r.outcome) == (int(big.steps[i]), int(big.outcome[i]))
        np.testing.assert_array_equal(r.contact_sets, big.contact_sets(i))
        np.testing.assert_array_equal(r.contact_times, big.set_times[big.set_offsets[i]:big.set_offsets[i + 1]])


def test_without_events_there_are_no_times():
    cfg = make_config("physical", t_max_s=0.3)
    r = simulate([10.0, 0.0, 0.0, 300.0, 0.0, 0.0], config=cfg)
    assert r.contact_times is None
    assert simulate_batch(np.zeros((2, 6)), config=cfg).set_times is None


@pytest.mark.parametrize("call", [
    lambda: simulate([0.0] * 6, preset="seed", events=True),
    lambda: simulate_batch(np.zeros((3, 6)), preset="physical", integrator="rk4", events=True),
    lambda: simulate([0.0] * 6, preset="physical", events="yes"),
])
def test_events_are_refused_where_there_are_none(call):
    with pytest.raises(ValueError, match="events"):
        call()


def _hermite(p, dp, h: float):
    """(z0, v0, z1, v1) of a height whose cubic over a sub-step of length h is p(θ), θ = t/h."""
    return p(0.0), dp(0.0) / h, p(1.0), dp(1.0) / h


def test_a_dip_inside_one_sub_step_has_two_crossings():
    # p(θ) = (θ − 0.3)(θ − 0.6)(θ + 1): above the ground at both ends, below it between 0.3 and 0.6
    def p(t):
        return (t - 0.3) * (t - 0.6) * (t + 1.0)

    def dp(t):
        return (t - 0.6) * (t + 1.0) + (t - 0.3) * (t + 1.0) + (t - 0.3) * (t - 0.6)

    roots = np.zeros(3)
    n, below = hermite_crossings(*_hermite(p, dp, 2e-4), 2e-4, 1e-6, roots)
    assert (n, below) == (2, False)
    np.testing.assert_allclose(roots[:2], [0.3, 0.6], rtol=0, atol=1e-14)


def test_crossings_at_the_cut_off_are_the_neighbouring_sub_steps():
    """A node left on the ground to rounding by a cut (a crossing within the cut-off of the start) and one that
    reaches it within the cut-off of the end are no crossings of this sub-step: the side after the start is."""
    roots = np.zeros(3)
    # starts 1e-17 below the ground, rises through it at once: above inside the sub-step
    n, below = hermite_crossings(-1e-17, 50.0, 0.01, 50.0, 2e-4, 1e-6, roots)
    assert (n, below) == (0, False)
    # falls onto the ground exactly at the end
    n, below = hermite_crossings(0.01, -50.0, -1e-17, -50.0, 2e-4, 1e-6, roots)
    assert (n, below) == (0, False)
    # one crossing in the middle, from below
    n, below = hermite_crossings(-0.005, 50.0, 0.005, 50.0, 2e-4, 1e-6, roots)
    assert (n, below) == (1, True)
    np.testing.assert_allclose(roots[0], 0.5, atol=1e-14)


def test_events_on_auto_without_a_gpu_run_on_the_cpu():
    """(On the GPU's events kernel under numba-cuda's simulator: tests/core/test_gpu.py.)"""
    b = simulate_batch(np.zeros((2, 6)), preset="physical", t_max_s=0.3, events=True, device="auto")
    assert b.device == "cpu" and b.set_times is not None
