"""The run loop (``core.loop``): crossing a free flight in one piece.

For a scheme whose free flight is exact the loop crosses a flight of
several whole steps in one exact piece.  These tests pin what that may and
may not change: the span it crosses is the longest one the free-flight
bound allows; a recording's rows inside it are the exact flight; the
tolerance weight ages as if stepped; and, against the same loop stepping
every flight step by step, the throws end alike (status, steps, outcome,
contact sets) with states that differ by rounding only.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.core import kernels, loop
from dicetrace.core._jit import _core_digest, jit
from dicetrace.core.free_flight import flight_steps, free_flight_safe
from dicetrace.core.schemes import scheme_module
from dicetrace.core.state import age_tolerance, new_states
from dicetrace.integrators import INTEGRATORS
from dicetrace.params import convert_l, make_config
from dicetrace.status import Status
from dicetrace.studies.study_accuracy import T_MAX_S, sample_ics

_CORE = _core_digest()[:16]
TSIT5 = INTEGRATORS["contact-tsit5"]


@jit
def _age(S, kp, h, steps, one_by_one):
    st = S[0]
    if one_by_one:
        for _ in range(steps):
            age_tolerance(st, kp, h, 1)
    else:
        age_tolerance(st, kp, h, steps)
    return st.tol_weight


@jit
def _steps(X, U, W, off, kp, h, mmax):
    return flight_steps(X, U, W, off, kp, h, mmax)


@jit
def _safe(X, U, W, off, kp, h):
    return free_flight_safe(X, U, W, off, kp, h)


_STEPPED: dict = {}


def stepped_loop(spec):
    """The summary loop of ``spec``'s scheme with every free flight stepped step by step (cached on disk)."""
    if spec.scheme not in _STEPPED:
        _STEPPED[spec.scheme] = loop.make_roll(scheme_module(spec), trace=False, exact_flight=False,
                                               name=f"roll_stepped_{spec.scheme}_{_CORE}")
    return _STEPPED[spec.scheme]


def _roll(kernel, ic, kin):
    """One throw through the run loop ``kernel`` in one call (no slice ends it): (summary, sets, set steps, S)."""
    cap = 1 << 14
    sets = np.zeros(cap, np.uint8)
    set_steps = np.zeros(cap, np.int32)
    S, Wk = kernels.new_roll_state(kin.integrator_id)
    status, steps, outcome, nsets = kernel(ic, kin.off0, kin.params, S, Wk, kernels.roll_out(sets, set_steps), False,
                                           1 << 62)
    return (int(status), int(steps), int(outcome)), sets[:nsets].copy(), set_steps[:nsets].copy(), S


def test_flight_steps_is_the_longest_span_the_bound_allows():
    """m steps are safe and m + 1 are not (or m is the cap), from states rising, falling, spinning and near the ground."""
    kp = make_config("physical").kernel_params()
    rng = np.random.default_rng(7)
    h = 1e-3
    counted = 0
    for _ in range(300):
        X = np.array([0.0, 0.0, rng.uniform(0.5, 30.0)])
        U = rng.normal(0.0, 60.0, 3)
        W = rng.normal(0.0, 30.0, 3)
        off = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float) * kp.half_side_cm
        mmax = int(rng.integers(1, 400))
        m = _steps(X, U, W, off, kp, h, mmax)
        assert 0 <= m <= mmax
        if m > 0:
            assert _safe(X, U, W, off, kp, m * h)
            counted += 1
        if m < mmax:
            assert not _safe(X, U, W, off, kp, (m + 1) * h)
    assert counted > 100  # the sample reaches both cases


@pytest.mark.parametrize("rate", [0.0, 10.0])
def test_the_tolerance_weight_ages_by_a_crossed_flight_as_by_its_steps(rate):
    kp = make_config("physical", tol=2e-8, tol_growth=rate).kernel_params()
    a, b = new_states(1), new_states(1)
    for steps in (1, 7, 150):
        assert _age(a, kp, 1e-3, steps, True) == _age(b, kp, 1e-3, steps, False)  # bit for bit
    assert a[0]["tol_weight"] == pytest.approx(math.exp(-rate * 0.158), rel=1e-12)


@pytest.mark.long  # the stepping loop is a second compile of contact-tsit5's summary loop (a minute on a cold cache)
def test_crossing_flights_changes_no_outcome_and_the_trajectory_only_by_rounding():
    """Against the same loop stepping every flight: same status, steps, outcome and contact sets; states
    within rounding at the end of a throw cut short at 0.25 s (before chaos amplifies the rounding)."""
    cfg = make_config("physical", t_max_s=T_MAX_S)
    ics = convert_l(sample_ics("zoom-out", 24), "program", "physical")
    kin = cfg.kernel_inputs(ics)
    crossing = kernels.roll_kernel(TSIT5.kernel_id, False)
    stepping = stepped_loop(TSIT5)
    for ic in kin.ics:
        a = _roll(crossing, ic, kin)
        b = _roll(stepping, ic, kin)
        assert a[0] == b[0]
        np.testing.assert_array_equal(a[1], b[1])
        np.testing.assert_array_equal(a[2], b[2])
    short = make_config("physical", t_max_s=0.25).kernel_inputs(ics[:8])
    moved = 0
    for ic in short.ics:
        sa = _roll(crossing, ic, short)[3][0]
        sb = _roll(stepping, ic, short)[3][0]
        for f in ("X", "U", "L", "off"):
            np.testing.assert_allclose(sa[f], sb[f], rtol=0, atol=1e-8 * max(1.0, np.abs(sb[f]).max()))
        moved += not np.array_equal(sa["off"], sb["off"])
    assert moved > 0  # the flights were crossed: the rounding differs


def test_a_recording_inside_a_crossed_flight_is_the_exact_flight_and_steers_nothing():
    """The rows of the first flight are the parabola and the exact rotation from the start; the traced
    throw ends exactly as its summary."""
    cfg = make_config("physical", t_max_s=T_MAX_S)
    ic = convert_l(sample_ics("zoom-out", 3), "program", "physical")[2]
    kin = cfg.kernel_inputs(ic[None, :])
    kp = kin.params
    n = int(kp.max_steps)
    tr_state = np.zeros((n + 1, loop.STATE_COLS))
    tr_force = np.zeros((n + 1, loop.FORCE_COLS))
    tr_energy = np.zeros((n + 1, loop.ENERGY_COLS))
    cap = 1 << 14
    sets, set_steps = np.zeros(cap, np.uint8), np.zeros(cap, np.int32)
    traced = kernels.run_roll(kin.ics[0], kin.off0, kp, TSIT5.kernel_id,
                              kernels.roll_out(sets, set_steps, None, tr_state, tr_force, tr_energy))
    summary = kernels.run_summary(kin.ics[0], kin.off0, kp, TSIT5.kernel_id, np.zeros(cap, np.uint8),
                               np.zeros(cap, np.int32))
    assert tuple(traced) == tuple(summary)
    first = int(set_steps[1])  # the step of the first contact
    assert first > 50
    t = np.arange(first) * kp.dt_s
    U0 = kin.ics[0, :3]
    z = kp.z0_cm + U0[2] * t + 0.5 * kp.g * t * t
    np.testing.assert_allclose(tr_state[:first, 2], z, rtol=0, atol=1e-11)
    np.testing.assert_allclose(tr_state[:first, 0], U0[0] * t, rtol=0, atol=1e-11)
    np.testing.assert_allclose(tr_state[:first, 5], U0[2] + kp.g * t, rtol=0, atol=1e-10)
    assert np.all(tr_force[:first] == 0.0)
    # rigid and turning at the constant ω: every offset keeps its length, the energy stays put
    off = tr_state[:first, 9:].reshape(-1, 8, 3)
    np.testing.assert_allclose(np.linalg.norm(off, axis=2), math.sqrt(3) * kp.half_side_cm, rtol=1e-13)
    e = tr_energy[1:first, 5]
    assert np.ptp(e) <= 1e-12 * np.abs(e).max()


# -- slices: a throw stopped every few steps and gone on with is the same throw ------------------------


def _one_call_and_sliced(kernel, ic, kin, budget, out_a, out_b):
    """``kernel`` on one throw in one call, and again in calls of ``budget`` steps each (resumed from its records)."""
    a = kernel(ic, kin.off0, kin.params, *kernels.new_roll_state(kin.integrator_id), out_a, False, 1 << 62)
    S, Wk = kernels.new_roll_state(kin.integrator_id)
    b = kernel(ic, kin.off0, kin.params, S, Wk, out_b, False, budget)
    calls = 1
    while b[0] == Status.RUNNING:
        assert b[1] < kin.params.max_steps
        b = kernel(ic, kin.off0, kin.params, S, Wk, out_b, True, budget)
        calls += 1
    return a, b, calls


def _slice_cases():
    """Every integrator × run loop; those whose loop ``tests/compile_kernels.py`` does not compile before the suite
    (the events loops of the schemes other than contact-tsit5's, forward Euler's summary loop: a minute or more
    of compiling each on a cold cache) in the long tier."""
    for integrator in INTEGRATORS:
        for kind in ("summary", "trace", "events"):
            cold = ((kind == "events" and INTEGRATORS[integrator].scheme != TSIT5.scheme)
                    or (kind == "summary" and integrator == "forward-euler"))
            yield pytest.param(integrator, kind, marks=[pytest.mark.long] if cold else [],
                               id=f"{kind}-{integrator}")


@pytest.mark.parametrize("integrator, kind", list(_slice_cases()))
def test_a_throw_in_slices_is_the_throw_in_one_call(integrator, kind):
    """Every run loop stopped every 37 steps (``Status.RUNNING``, its state kept in its motion and work records)
    and gone on with gives the throw of one call bit for bit: status, steps, outcome, contact sets (events and
    their times), trace rows; through free flights crossed in one piece, dense-output fronts and the events'
    buffers."""
    spec = INTEGRATORS[integrator]
    if kind == "events" and not kernels.has_events(spec.kernel_id):
        pytest.skip("no events loop")
    cfg = make_config("physical", integrator=integrator, t_max_s=1.5 if integrator == "forward-euler" else 8.0)
    ics = convert_l(sample_ics("zoom-out", 3), "program", "physical")
    kin = cfg.kernel_inputs(ics)
    k = kernels.kernels_for(spec.kernel_id)
    kernel = {"summary": k.roll_summary, "trace": k.roll_trace, "events": k.roll_events}[kind]
    rows = int(kin.params.max_steps) + 1 if kind == "trace" else 0

    def out():
        cap = 1 << 12
        return kernels.roll_out(np.zeros(cap, np.uint8), np.zeros(cap, np.int32),
                                np.zeros(cap) if kind == "events" else None,
                                np.zeros((rows, loop.STATE_COLS)), np.zeros((rows, loop.FORCE_COLS)),
                                np.zeros((rows, loop.ENERGY_COLS)))

    sliced = 0
    for ic in kin.ics:
        oa, ob = out(), out()
        a, b, calls = _one_call_and_sliced(kernel, ic, kin, 37, oa, ob)
        assert tuple(map(int, a)) == tuple(map(int, b))
        n = int(a[3])
        for x, y in zip(oa, ob):
            np.testing.assert_array_equal(x[:n] if x.ndim == 1 else x, y[:n] if y.ndim == 1 else y)
        sliced += calls > 3
    assert sliced == len(kin.ics)  # every throw went through several slices


def test_batch_goes_on_with_the_throws_a_slice_stopped(monkeypatch):
    """``run_batch`` with slices of 50 steps (the seed path's specialised kernel stops at the budget, keeps nothing,
    and the throw starts again in the run loop; the others go on from their records): the results of slices
    long enough for every throw, bit for bit."""
    for preset, integrator in (("seed", None), ("physical", None), ("physical", "verlet")):
        cfg = make_config(preset, **({} if integrator is None else {"integrator": integrator}))
        kin = cfg.kernel_inputs(convert_l(sample_ics("zoom-out", 40), "program", cfg.preset.l_convention))
        whole = kernels.batch_out(40, 64)
        kernels.run_batch(kin.ics, kin.off0, kin.params, kin.integrator_id, 64, whole)
        monkeypatch.setattr(kernels, "SLICE_STEPS", 50)
        monkeypatch.setattr(kernels, "SUMMARY_SLICES", 1)
        sliced = kernels.batch_out(40, 64)
        kernels.run_batch(kin.ics, kin.off0, kin.params, kin.integrator_id, 64, sliced)
        monkeypatch.undo()
        assert whole.steps.min() > 50  # every throw outlived its first slice
        for x, y in zip(whole, sliced):
            np.testing.assert_array_equal(x, y)


def test_a_flight_that_never_lands_is_crossed_at_once():
    """g = 0 and a die thrown up: one free flight to the time cap of 1e7 s (1e10 steps of 1 ms), crossed in one
    piece; the tolerance weight (tol_growth > 0, ``state.age_tolerance``) stops ageing at its floor instead of
    multiplying 1e10 times, so the throw ends at once, at the time cap."""
    cfg = make_config("physical", g=0.0, t_max_s=1e7)
    assert cfg.numerics.tol_growth > 0
    kin = cfg.kernel_inputs(np.array([[0.0, 0.0, 50.0, 0.0, -100.0, 0.0]]))
    cap = 64
    r = kernels.run_summary(kin.ics[0], kin.off0, kin.params, kin.integrator_id, np.zeros(cap, np.uint8),
                            np.zeros(cap, np.int32))
    assert r[0] == Status.TIME_CAP and r[1] == int(kin.params.max_steps)


@pytest.mark.parametrize("preset, integrator, body", [
    ("seed", "forward-euler", {}),  # unstable: it never settles, so the cap ends it
    ("physical", "contact-tsit5", {}),
    ("physical", "contact-tsit5", dict(half_extents_cm=(1.0, 0.8, 0.6), load_fraction=0.2, load_cm=(0.3, -0.6, 0.2))),
])
def test_the_time_cap_ends_a_throw_at_t_max_whatever_its_stop_threshold(preset, integrator, body):
    """A throw still moving at t_max ends there, after exactly t_max/dt steps, in one call and in a batch: the
    stop threshold (about 2598 in energy units for the cube) is never taken for the last step of a slice."""
    from dicetrace.simulate import simulate, simulate_batch

    t_max = 3.0 if preset == "physical" else 2.0
    cfg = make_config(preset, integrator=integrator, t_max_s=t_max, g=-98.0 if preset == "physical" else -980.0,
                      **body)
    ic = np.array([80.0, 20.0, 0.0, 30.0, -40.0, 20.0])
    r = simulate(ic, config=cfg)
    b = simulate_batch(ic[None, :], config=cfg)
    want = round(t_max / cfg.numerics.dt_s)
    assert (r.status, r.steps) == ("time_cap", want)
    assert (b.status[0], int(b.steps[0])) == ("time_cap", want)
