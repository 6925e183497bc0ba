"""Every integrator against analytic answers: convergence orders, the bouncing node, rigidity.

The order tests step the real kernels (each scheme's ``step``) with a
small driver that, unlike the program's loop, evaluates the forces at the
initial state (the loop starts with zero forces, which would spoil the order
of a segment that starts in contact).  The "single node" is the die dropped
flat with zero spin: its four bottom corners touch the ground together and
move as one node of mass 2 on a spring k (ω² = 4k/8 = k/2), with gravity and
friction off where a closed form is wanted.

Errors are regressed on log2(h) as in diffrax's ``test_ode_order``; each
integrator must reach its declared order (``IntegratorSpec.order``).
"""

from __future__ import annotations

import math
import weakref

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from dicetrace.core._jit import _core_digest, jit
from dicetrace.core.forces import eval_forces
from dicetrace.core.model import energy_dynamic, init_offsets
from dicetrace.core.schemes import scheme_module, step_of
from dicetrace.core.state import new_states, new_work
from dicetrace.params import INTEGRATORS, Config, Numerics, Preset, make_config

ALL = tuple(INTEGRATORS)
#: Integrators whose accuracy is set by dt (the adaptive ones' by their tolerance).
BY_DT = tuple(name for name, spec in INTEGRATORS.items() if not spec.adaptive)
#: Integrators with error-controlled sub-steps.
ADAPTIVE = tuple(name for name, spec in INTEGRATORS.items() if spec.adaptive)


#: Named by the digest of dicetrace.core (what ``_jit`` stamps core's own cached kernels with), so a
#: change to a scheme compiles a new driver instead of loading one that has the old step linked in.
_CORE = _core_digest()[:16]
_DRIVERS: dict = {}


def _make_drive(scheme):
    def drive(kp, h, nstep, S, Wk, zmin, zmax):
        """Step ``nstep`` times from the state S[0] (work record Wk[0]) in place with ``scheme.step``; track each
        node's height range.

        Compiled per scheme by :func:`driver` (the scheme module closed over).
        """
        st = S[0]
        wk = Wk[0]
        below, mask = eval_forces(st, kp)
        # through an array, as the run loop does: the step then compiles for a plain bool only, not
        # also for the literal False that type inference sees first (a second compile of every step)
        flag = np.empty(1, np.bool_)
        flag[0] = below
        contact = flag[0]
        for _ in range(nstep):
            contact, mask = scheme.step(st, wk, kp, h, contact)
            for k in range(8):
                zmin[k] = min(zmin[k], st.z[k])
                zmax[k] = max(zmax[k], st.z[k])
        return True

    drive.__name__ = drive.__qualname__ = f"drive_{scheme.__name__.rsplit('.', 1)[-1]}_{_CORE}"
    return jit(drive)


#: The work record that goes with a motion record S (what a scheme keeps between steps, a dense-output front
#: included, lives there): by id(S), with a weak reference to S so that a new array never inherits an old one's.
_WORK: dict = {}


def work_of(S, work_dtype):
    """The work record (1,) of the scheme's dtype that goes with the motion record S, made on first use."""
    held = _WORK.get(id(S))
    if held is None or held[0]() is not S or held[1].dtype != work_dtype:
        held = _WORK[id(S)] = (weakref.ref(S), new_work(work_dtype))
    return held[1]


def driver(integ):
    """A driver of the scheme of ``integ`` (cached on disk like the kernels, built on first use): steps
    ``nstep`` times from S[0] in place (in S's own work record of the scheme, :func:`work_of`) and tracks each
    node's height range."""
    scheme = INTEGRATORS[integ].scheme
    if scheme not in _DRIVERS:
        mod = scheme_module(INTEGRATORS[integ])
        jitted = _make_drive(mod)
        _DRIVERS[scheme] = lambda kp, h, nstep, S, zmin, zmax: jitted(kp, h, nstep, S, work_of(S, mod.WORK), zmin,
                                                                      zmax)
    return _DRIVERS[scheme]


def state(kp, X0, U0, L0, off=None):
    """A (1,) state record at (X0, U0, L0) with the program's offsets (or ``off``)."""
    S = new_states(1)
    S["X"][0] = X0
    S["U"][0] = U0
    S["L"][0] = L0
    S["W"][0] = np.asarray(L0, float) / kp.inertia
    if off is None:
        init_offsets(kp.half_side_cm, S["off"][0])
    else:
        S["off"][0] = off
    S["rot_h"] = -1.0
    return S


def kparams(substeps: int = 8, integrator: str = "semi-implicit-euler", tol: float = 1e-7, tol_growth: float = 0.0,
            **preset):
    numerics = Numerics(integrator=integrator, substeps=substeps, tol=tol, tol_growth=tol_growth)
    return Config(preset=Preset(name="test", **preset), numerics=numerics).kernel_params()


def run(integ, kp, h, t_end, X0, U0, L0, clock=0.0):
    """State after t_end (a multiple of h): X, U, L, offsets, node z ranges (``clock``: the throw's time at the start)."""
    S = state(kp, X0, U0, L0)
    S["tol_weight"] = math.exp(-kp.tol_growth * clock)
    zmin = np.full(8, np.inf)
    zmax = np.full(8, -np.inf)
    n = int(round(t_end / h))
    assert abs(n * h - t_end) < 1e-12 * t_end
    assert driver(integ)(kp, h, n, S, zmin, zmax)
    st = S[0]
    return st["X"].copy(), st["U"].copy(), st["L"].copy(), st["off"].copy(), zmin, zmax


def slopes(hs, errs):
    """Local slopes of log2(err) against log2(h) between consecutive steps."""
    return np.diff(np.log2(errs)) / np.diff(np.log2(hs))


def test_every_table_row_has_a_compiled_step():
    """Each row of the integrator table names a scheme with a real step: one free-flight
    step of every row's step function moves the die along the exact parabola."""
    cfg = make_config("seed")
    kp = cfg.kernel_params()
    for name, spec in INTEGRATORS.items():
        assert callable(step_of(spec)), name
        h = 1e-3
        # one step through the stepping driver, which calls the scheme's step as the run loop does (a call from
        # Python would compile the step once more, for Python's argument types: ~20 s a scheme on a cold cache)
        X, _, _, _, zmin, _ = run(name, kp, h, h, [0.0, 0.0, 15.0], [10.0, -5.0, 30.0], np.zeros(3))
        assert zmin.min() > 0.0, name
        exact = 15.0 + 30.0 * h + 0.5 * kp.g * h * h
        np.testing.assert_allclose(X[:2], [10.0 * h, -5.0 * h], rtol=0, atol=1e-15, err_msg=name)
        # exact for the order >= 2 schemes (free flight is a parabola); the
        # first-order ones are off by ½·g·h² (sign depends on the scheme)
        tol = 1e-12 if spec.order > 1 else 0.5 * abs(kp.g) * h * h * (1 + 1e-9)
        assert abs(X[2] - exact) <= tol, (name, X[2] - exact)


# -- free flight: parabola and exact rotation ---------------------------------------------------


@pytest.mark.parametrize("integ", ALL)
def test_free_flight_order(integ):
    """Free flight: X = X0 + U0·t + g·t²/2, offsets turned by ω·t (ω = −L_program/I).

    Verlet, RK4 and contact-substep are exact here (quadratic in t, constant
    ω); the Euler schemes are first order (their position lags by g·h·t/2).
    """
    kp = kparams(integrator=integ)
    T = 0.125
    U0, L0 = np.array([30.0, -20.0, 50.0]), np.array([80.0, -60.0, 120.0])
    x_exact = np.array([0.0, 0.0, 15.0]) + U0 * T + np.array([0.0, 0.0, 0.5 * kp.g * T * T])
    u_exact = U0 + np.array([0.0, 0.0, kp.g * T])
    off_exact = np.empty((8, 3))
    init_offsets(1.0, off_exact)
    off_exact = Rotation.from_rotvec(-L0 / kp.inertia * T).apply(off_exact)
    hs = T / 2.0 ** np.arange(4, 10)
    errs = []
    for h in hs:
        X, U, L, off, zmin, _ = run(integ, kp, h, T, [0, 0, 15.0], U0, L0)
        assert zmin.min() > 0  # no contact: a free-flight segment
        errs.append(max(np.abs(X - x_exact).max(), np.abs(U - u_exact).max() / 100, np.abs(off - off_exact).max()))
    errs = np.array(errs)
    if INTEGRATORS[integ].order == 1:
        assert np.all(np.abs(slopes(hs, errs) - 1.0) < 0.05), errs
    else:
        assert errs.max() < 1e-12, errs  # exact to rounding


# -- the single undamped node on the penalty spring ------------------------------------------------

T_CONTACT = 2.0**-6  # contact duration π/ω of the bounce test, s
K_BOUNCE = 2.0 * (math.pi / T_CONTACT) ** 2  # so that ω = √(k/2) = π / T_CONTACT


@pytest.mark.parametrize("integ", BY_DT)
def test_undamped_bounce_order(integ):
    """Die dropped flat at 100 cm/s onto an undamped, frictionless spring, no gravity.

    Exact: contact from t = 0 to π/ω = T_CONTACT (both on the step grid),
    exit speed = entry speed, then free flight: at 2·T_CONTACT the die is at
    z = half + v·T_CONTACT moving up at v.  The exit/entry speed ratio → 1 and
    the height error both converge at (at least) the integrator's order.
    """
    kp = kparams(k=K_BOUNCE, gamma=0.0, mu=0.0, g=0.0)
    v = 100.0
    j = np.arange(3, 9) if integ != "contact-substep" else np.arange(0, 5)
    hs = T_CONTACT / 2.0**j
    ratio_err, z_err = [], []
    for h in hs:
        X, U, L, off, zmin, zmax = run(integ, kp, h, 2 * T_CONTACT, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
        assert zmin[[0, 2, 4, 6]].max() < 0 and zmax[[1, 3, 5, 7]].min() > 0  # the four bottom nodes bounced
        ratio_err.append(abs(U[2] / v - 1.0))
        z_err.append(abs(X[2] - (1.0 + v * T_CONTACT)))
    order = INTEGRATORS[integ].order
    for errs in (np.array(ratio_err), np.array(z_err)):
        keep = errs > 1e-13  # above rounding
        s = slopes(hs[keep], errs[keep])
        assert len(s) >= 3 and np.all(s[-3:] > order - 0.15), (errs, s)
    assert ratio_err[-1] < {1: 0.05, 2: 1e-6, 4: 1e-9}[order]


# -- the damped node: restitution -------------------------------------------------------------------


def restitution_exact(gamma: float, v: float) -> float:
    """Exit/entry speed ratio of d'' = −ω²·d·(1 + γ·d'), d the penetration, d'(0) = v.

    The program's normal force P = k·d·(1 − γ·u_z) with u_z = −d' (Hunt–Crossley
    damping, proportional to the force).  With w = d': w·dw/dd = −ω²·d·(1 + γw),
    so ∫ w/(1 + γw) dw = −ω² ∫ d dd, i.e. w/γ − ln(1 + γw)/γ² + ω²d²/2 is
    conserved.  At entry and exit d = 0, so a = γv and b = γ·w_exit satisfy
    b − ln(1 + b) = a − ln(1 + a) with −1 < b < 0, and e = −b/a.  ω (hence k)
    drops out: the restitution depends on γ·v only.  (Cf. K. H. Hunt and
    F. R. E. Crossley, J. Appl. Mech. 42 (1975) 440; the same first integral
    appears in Marhefka & Orin, IEEE Trans. SMC-A 29 (1999) 566.)
    """
    a = gamma * v
    c = a - math.log1p(a)
    b = brentq(lambda b: b - math.log1p(b) - c, -1.0 + 1e-15, -1e-15, xtol=1e-17, rtol=1e-15)
    return -b / a


def test_restitution_formula_sanity():
    # small damping: e ≈ 1 − (2/3)·γv (expand b − ln(1+b) to third order)
    assert restitution_exact(1e-4, 1.0) == pytest.approx(1 - 2 / 3 * 1e-4, rel=1e-7)
    assert 0.74 < restitution_exact(0.005, 100.0) < 0.76


@pytest.mark.parametrize("integ", BY_DT)
def test_damped_restitution_converges(integ):
    """Restitution of the damped flat drop → the exact value, the same for k = 5e5 and 5e6."""
    gamma, v = 0.005, 100.0
    e_exact = restitution_exact(gamma, v)
    first = {"forward-euler": 6, "semi-implicit-euler": 3, "verlet": 3, "rk4": 3, "contact-substep": 0}[integ]
    for k in (5e5, 5e6):
        kp = kparams(k=k, gamma=gamma, mu=0.0, g=0.0)
        tc = math.pi / math.sqrt(k / 2.0)
        errs = []
        for j in range(first, first + 5):
            h = tc / 2.0**j
            X, U, L, off, zmin, _ = run(integ, kp, h, 3 * tc, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
            assert zmin.min() < 0
            errs.append(abs(U[2] / v - e_exact))
        tol = {"forward-euler": 0.01, "semi-implicit-euler": 2e-3, "verlet": 2e-4, "rk4": 1e-4, "contact-substep": 1e-8}
        assert errs[-1] < tol[integ], errs
        assert errs[-1] < 0.2 * errs[0] or errs[-1] < 1e-12, errs


def test_contact_substep_restitution_independent_of_k():
    gamma, v = 0.005, 100.0
    out = []
    for k in (5e5, 5e6, 5e7):
        kp = kparams(k=k, gamma=gamma, mu=0.0, g=0.0)
        tc = math.pi / math.sqrt(k / 2.0)
        X, U, *_ = run("contact-substep", kp, tc / 16, 3 * tc, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
        out.append(U[2] / v)
    assert np.ptp(out) < 1e-9 and out[0] == pytest.approx(restitution_exact(gamma, v), abs=1e-8)


# -- a smooth contact segment with torques: the Lie-group order ------------------------------------


@pytest.mark.parametrize("integ", BY_DT)
def test_smooth_contact_order(integ):
    """Die resting on its four bottom corners, sliding, spinning and rocking for 1/32 s.

    All four corners stay below the ground and the other four above, the
    per-node friction is regularised (v_reg = 10 cm/s) and the normal force
    stays positive: the right-hand side is smooth, with friction torques
    about every axis.  Error against RK4 at h = T/2¹³ (for RK4 itself,
    against contact-substep at the same fine sub-step, an independent code
    path): Lie-group RK4 must show order 4, Verlet 2, the Euler schemes 1.
    """
    kp = kparams(friction="per-node", clamp_normal=True, energy="rigid", v_reg_cm_s=10.0)
    d_eq = 8 * 980.0 / (4 * kp.k)
    T = 2.0**-5
    X0, U0, L0 = [0, 0, 1 - d_eq], [3.0, -2.0, 0.3], [0.8, -0.6, 12.0]
    ref_integ = "rk4" if integ != "rk4" else "contact-substep"
    ref_h = T / 2**13 if ref_integ == "rk4" else T / 2**10
    Xr, Ur, Lr, offr, *_ = run(ref_integ, kp, ref_h, T, X0, U0, L0)
    j = np.arange(7, 11) if integ == "forward-euler" else np.arange(5, 9)
    if integ == "contact-substep":
        j = np.arange(3, 7)
    hs = T / 2.0**j
    errs = []
    for h in hs:
        X, U, L, off, zmin, zmax = run(integ, kp, h, T, X0, U0, L0)
        assert zmax[[0, 2, 4, 6]].max() < 0 and zmin[[1, 3, 5, 7]].min() > 0
        errs.append(max(np.abs(X - Xr).max(), np.abs(U - Ur).max() / 100, np.abs(L - Lr).max() / 100, np.abs(off - offr).max()))
    s = slopes(hs, np.array(errs))
    order = INTEGRATORS[integ].order
    lo = 0.8 if integ == "forward-euler" else order - 0.2
    assert np.all(s[-2:] > lo) and np.all(s[-2:] < order + 0.6), (errs, s)


# -- rigidity ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("preset", ["seed", "physical"])
@pytest.mark.parametrize("integ", ALL)
def test_rigidity(integ, preset):
    """The offsets stay a rigid cube (all pairwise distances, to 1e-10 cm) on a whole throw."""
    from dicetrace.ics import seed_slice
    from dicetrace.simulate import Record, simulate

    ic = seed_slice(1.65, 3.9)
    if preset == "physical":
        ic = ic * np.array([1, 1, 1, -1, -1, -1])
    r = simulate(ic, preset=preset, integrator=integ, dt_s=1e-3, t_max_s=5.0, record=Record(states=True, energy=False))
    off = r.trace.node_offsets
    gram0 = off[0] @ off[0].T
    gram = np.einsum("nki,nli->nkl", off, off)
    assert np.abs(gram - gram0).max() < 1e-10
    assert r.steps > 100


# -- the summary fast path of contact-substep -------------------------------------------------------


@pytest.mark.parametrize("integ_name", ["contact-substep", "contact-adaptive"])
@pytest.mark.parametrize("preset", ["seed", "physical"])
def test_contact_substep_fast_path_identical(preset, integ_name):
    """The summary loop of contact-substep (what ``run_summary``/``run_batch`` run for
    its summaries: the run loop compiled without trace code) equals the tracing loop
    ``run_roll`` bit for bit: status, steps, outcome and the whole
    contact-set sequence, on tilted and flat starts."""
    from dicetrace.core import kernels
    from dicetrace.ics import seed_slice
    from dicetrace.params import make_config

    rng = np.random.default_rng(3)
    tol = {"tol": 1e-6} if INTEGRATORS[integ_name].adaptive else {}
    cfg = make_config(preset, integrator=integ_name, dt_s=2e-3, t_max_s=10.0, **tol)
    kp = cfg.kernel_params()
    assert (kp.tol > 0) == (integ_name == "contact-adaptive")
    integ = INTEGRATORS[integ_name].kernel_id
    sign = np.array([1, 1, 1, -1, -1, -1]) if preset == "physical" else np.ones(6)
    ics = [seed_slice(1.65, 3.9) * sign] + [seed_slice(*rng.uniform([1.0, 3.0], [2.5, 5.0])) * sign for _ in range(5)]
    orients = [None, Rotation.from_euler("xyz", [0.3, -0.2, 0.1]).as_matrix()]
    settled = 0
    for orient in orients:
        off0 = cfg.initial_offsets(orient)
        for ic in ics:
            ic = np.asarray(ic, float)
            a = (np.zeros(256, np.uint8), np.zeros(256, np.int32))
            b = (np.zeros(256, np.uint8), np.zeros(256, np.int32))
            ra = kernels.roll_kernel(integ, False)(ic, off0, kp, *kernels.new_roll_state(integ), kernels.roll_out(*a),
                                                   False, kernels.SLICE_STEPS)
            rb = kernels.run_roll(ic, off0, kp, integ, kernels.roll_out(*b))
            assert ra == rb
            n = ra[3]
            assert np.array_equal(a[0][:n], b[0][:n]) and np.array_equal(a[1][:n], b[1][:n])
            settled += ra[0] == 0  # SETTLED
    assert settled >= 6


# -- contact-adaptive: error control ------------------------------------------------------------------


def test_adaptive_undamped_bounce_tolerance_proportional():
    """The undamped flat bounce of test_undamped_bounce_order under error control.

    dt = T_CONTACT only caps the sub-steps; the error follows the tolerance:
    it falls monotonically and roughly in proportion (a local-error control
    of an order-4 step gives global error ∝ tol^(4/4 .. 4/5)), down to the
    1e-10 level, and exit speed = entry speed to 1e-9 at tol = 1e-10.
    """
    v = 100.0
    tols = 10.0 ** -np.arange(4, 11)
    ratio_err, z_err = [], []
    for tol in tols:
        kp = kparams(integrator="contact-adaptive", tol=tol, k=K_BOUNCE, gamma=0.0, mu=0.0, g=0.0)
        X, U, L, off, zmin, zmax = run("contact-adaptive", kp, T_CONTACT / 2, 2 * T_CONTACT, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
        assert zmin[[0, 2, 4, 6]].max() < 0 and zmax[[1, 3, 5, 7]].min() > 0
        ratio_err.append(abs(U[2] / v - 1.0))
        z_err.append(abs(X[2] - (1.0 + v * T_CONTACT)))
    for errs in (np.array(ratio_err), np.array(z_err)):
        s = slopes(tols, errs)
        assert np.all(np.diff(errs) < 0), errs
        assert 0.6 < np.polyfit(np.log(tols), np.log(errs), 1)[0] < 1.3, (errs, s)
    assert ratio_err[-1] < 1e-9


@pytest.mark.parametrize("integ", ADAPTIVE)
def test_tol_growth_loosens_the_tolerance_with_the_throws_clock(integ):
    """tol_growth: a step starting at time t of the throw weighs its error estimates by exp(−rate·t).

    The undamped bounce of the test above, run with tol 1e-9 and a slow rate
    late on the clock (t = ln(100)/rate), is the bounce at a uniform tol of
    1e-7; later still it is held at TOL_LOOSEST (1e-5); at t = 0 it is the
    bounce at 1e-9.  Each step moves the weight on by its length (while the rate is above 0).
    """
    from dicetrace.params import TOL_LOOSEST

    v, rate = 100.0, 1e-3

    def bounce_error(tol, growth=0.0, clock=0.0):
        kp = kparams(integrator=integ, tol=tol, tol_growth=growth, k=K_BOUNCE, gamma=0.0, mu=0.0, g=0.0)
        X, U, *_ = run(integ, kp, T_CONTACT / 2, 2 * T_CONTACT, [0, 0, 1.0], [0, 0, -v], [0, 0, 0], clock=clock)
        return abs(U[2] / v - 1.0)

    tight, loose, loosest = bounce_error(1e-9), bounce_error(1e-7), bounce_error(TOL_LOOSEST)
    assert loose > 10 * tight and loosest > 10 * loose  # the three tolerances give three different bounces
    late = bounce_error(1e-9, rate, clock=math.log(100.0) / rate)
    later = bounce_error(1e-9, rate, clock=math.log(1e8) / rate)  # 1e-1 unbounded: held at 1e-5
    start = bounce_error(1e-9, rate, clock=0.0)
    assert abs(math.log(late / loose)) < 0.1, (late, loose)
    assert abs(math.log(later / loosest)) < 0.1, (later, loosest)
    assert abs(math.log(start / tight)) < 0.1, (start, tight)
    kp = kparams(integrator=integ, tol=1e-9, tol_growth=rate, k=K_BOUNCE, gamma=0.0, mu=0.0, g=0.0)
    S = state(kp, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
    driver(integ)(kp, T_CONTACT / 2, 4, S, np.full(8, np.inf), np.full(8, -np.inf))
    assert S["tol_weight"][0] == pytest.approx(math.exp(-rate * 2 * T_CONTACT), rel=1e-12)


#: Per error-controlled scheme: tolerances, and the restitution error the tightest must reach
#: (DOP853 reaches 2e-12 at tol 1e-10, a 4e-9 at 1e-6; RK4's estimate is looser).
RESTITUTION_TOLS = {
    "contact-adaptive": ((1e-5, 1e-7, 1e-9), 1e-8),
    "contact-dop853": ((1e-6, 1e-8, 1e-10), 2e-11),
    "contact-tsit5": ((1e-6, 1e-8, 1e-10), 2e-10),
}


@pytest.mark.parametrize("integ", ADAPTIVE)
@pytest.mark.parametrize("k", [5e5, 5e6])
def test_adaptive_damped_restitution(k, integ):
    """Damped flat drop under error control: the exact restitution, for any k, to ~tol."""
    gamma, v = 0.005, 100.0
    e_exact = restitution_exact(gamma, v)
    tc = math.pi / math.sqrt(k / 2.0)
    tols, bound = RESTITUTION_TOLS[integ]
    errs = []
    for tol in tols:
        kp = kparams(integrator=integ, tol=tol, k=k, gamma=gamma, mu=0.0, g=0.0)
        X, U, *_ = run(integ, kp, tc / 4, 3 * tc, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
        errs.append(abs(U[2] / v - e_exact))
    assert errs[-1] < bound and errs[-1] < 0.01 * errs[0], errs


def test_adaptive_smooth_contact_follows_tolerance():
    """The smooth four-corner contact of test_smooth_contact_order (friction torques on
    every axis): the error against RK4 at h = T/2¹³ falls with the tolerance, to 1e-9."""
    kp0 = kparams(friction="per-node", clamp_normal=True, energy="rigid", v_reg_cm_s=10.0)
    d_eq = 8 * 980.0 / (4 * kp0.k)
    T = 2.0**-5
    X0, U0, L0 = [0, 0, 1 - d_eq], [3.0, -2.0, 0.3], [0.8, -0.6, 12.0]
    Xr, Ur, Lr, offr, *_ = run("rk4", kp0, T / 2**13, T, X0, U0, L0)
    errs = []
    for tol in (1e-4, 1e-6, 1e-8, 1e-10):
        kp = kparams(integrator="contact-adaptive", tol=tol, friction="per-node", clamp_normal=True, energy="rigid", v_reg_cm_s=10.0)
        X, U, L, off, zmin, zmax = run("contact-adaptive", kp, T / 4, T, X0, U0, L0)
        assert zmax[[0, 2, 4, 6]].max() < 0 and zmin[[1, 3, 5, 7]].min() > 0
        errs.append(max(np.abs(X - Xr).max(), np.abs(U - Ur).max() / 100, np.abs(L - Lr).max() / 100, np.abs(off - offr).max()))
    assert np.all(np.diff(errs) < 0) and errs[-1] < 1e-9, errs


def test_adaptive_matches_reference_on_throws():
    """Whole physical throws: contact-adaptive at tol = 1e-11 and fixed sub-steps of
    dt/128 (finer than the accuracy study's reference) converge to the same throws:
    same outcomes, settle times within a step of their common 1 ms stop-test grid.
    (At tol = 1e-9 one throw of these settles 11 ms late: settling of the physical
    preset is slow rocking, whose threshold crossing moves with tiny differences.)"""
    from dicetrace.ics import seed_slice
    from dicetrace.params import PRESETS
    from dicetrace.simulate import simulate_batch

    rng = np.random.default_rng(11)
    ics = np.array([seed_slice(*rng.uniform([1.0, 3.0], [2.5, 5.0])) * [1, 1, 1, -1, -1, -1] for _ in range(6)])
    a = simulate_batch(ics, preset="physical", integrator="contact-adaptive", dt_s=1e-3, t_max_s=10.0, tol=1e-11)
    fine = Numerics(integrator="contact-substep", dt_s=1e-3, t_max_s=10.0, substeps=128)
    b = simulate_batch(ics, config=Config(preset=PRESETS["physical"], numerics=fine))
    assert (a.status == "settled").all() and (b.status == "settled").all()
    assert np.array_equal(a.outcome, b.outcome)
    assert np.abs(a.t_settle_s - b.t_settle_s).max() <= 1e-3 + 1e-12


# -- contact-dop853: the order-8 pair on the quaternion state ---------------------------------------


def fixed_substeps(integ, **preset):
    """Kernel parameters of the error-controlled ``integ`` with fixed sub-steps of one macro step (tol = 0: no error control)."""
    return kparams(integrator=integ, **preset)._replace(tol=0.0, substeps=1.0)


#: The smooth contact of ``test_smooth_contact_order`` (per-node friction, all four bottom corners in the ground).
SMOOTH = dict(friction="per-node", clamp_normal=True, energy="rigid", v_reg_cm_s=10.0)
SMOOTH_T = 2.0**-5


def smooth_contact_errors(integ, kp, hs):
    """Errors of ``integ`` (kernel parameters kp) at the steps hs over SMOOTH_T of the smooth
    contact, against contact-substep at SMOOTH_T/2¹⁰ (the contact stays smooth throughout)."""
    kr = kparams(**SMOOTH)
    d_eq = 8 * 980.0 / (4 * kr.k)
    X0, U0, L0 = [0, 0, 1 - d_eq], [3.0, -2.0, 0.3], [0.8, -0.6, 12.0]
    Xr, Ur, Lr, offr, *_ = run("contact-substep", kr, SMOOTH_T / 2**10, SMOOTH_T, X0, U0, L0)
    errs = []
    for h in hs:
        X, U, L, off, zmin, zmax = run(integ, kp, h, SMOOTH_T, X0, U0, L0)
        assert zmax[[0, 2, 4, 6]].max() < 0 and zmin[[1, 3, 5, 7]].min() > 0
        errs.append(max(np.abs(X - Xr).max(), np.abs(U - Ur).max() / 100, np.abs(L - Lr).max() / 100, np.abs(off - offr).max()))
    return np.array(errs)


def bounce_ratio_errors(integ, kp, hs, v=100.0):
    """|exit/entry speed − 1| of the undamped flat bounce of test_undamped_bounce_order at the steps hs."""
    out = []
    for h in hs:
        X, U, L, off, zmin, zmax = run(integ, kp, h, 2 * T_CONTACT, [0, 0, 1.0], [0, 0, -v], [0, 0, 0])
        assert zmin[[0, 2, 4, 6]].max() < 0 and zmax[[1, 3, 5, 7]].min() > 0
        out.append(abs(U[2] / v - 1.0))
    return np.array(out)


def test_dop853_smooth_contact_order_8():
    """The smooth sliding, spinning, rocking contact of ``test_smooth_contact_order`` with
    fixed DOP853 steps: the error against contact-substep at T/2¹³ sub-steps falls at
    order 8 (local slopes 8.2–8.8 measured) until it nears that reference's own error."""
    hs = SMOOTH_T / 2.0 ** np.arange(2, 6)
    errs = smooth_contact_errors("contact-dop853", fixed_substeps("contact-dop853", **SMOOTH), hs)
    s = slopes(hs, errs)
    assert np.all(s > 7.8) and np.all(s < 9.5), (errs, s)
    assert errs[-1] < 1e-10


def test_dop853_undamped_bounce_converges():
    """The undamped flat bounce with fixed DOP853 steps: exit/entry speed ratio → 1.

    Order 6 here, not 8: the kinks of the penalty force (a node entering or
    leaving the ground) are located on the cubic Hermite interpolant of the
    node's height, so the steps next to a contact change carry a
    lower-order error (measured slopes 5.1, 5.8, 6.0).
    """
    hs = T_CONTACT / 2.0 ** np.arange(2, 6)
    ratio_err = bounce_ratio_errors("contact-dop853", fixed_substeps("contact-dop853", k=K_BOUNCE, gamma=0.0, mu=0.0, g=0.0), hs)
    s = slopes(hs, ratio_err)
    assert np.all(s[-2:] > 5.5), (ratio_err, s)
    assert ratio_err[-1] < 1e-11


def set_down_on_a_face(integ, kp, h, t_end=10.0):
    """A die set down on a face 1.5× too deep, sliding and spinning, stepped by ``integ`` in
    steps of h for t_end: the state, the dynamics' energy and the CM after each step, and
    each node's highest point."""
    d_eq = 8 * abs(kp.g) / (4 * kp.k)
    S = state(kp, [0, 0, 1 - 1.5 * d_eq], [2.0, -1.0, 0.0], [0.0, 0.0, 3.0])
    n = int(round(t_end / h))
    E = np.zeros(n)
    Xs = np.zeros((n, 3))
    drive = driver(integ)
    zmin, zmax = np.full(8, np.inf), np.full(8, -np.inf)
    for i in range(n):  # one step per call
        assert drive(kp, h, 1, S, zmin, zmax)
        st = S[0]
        E[i] = energy_dynamic(*st["U"], *st["W"], *st["L"], st["z"], kp)
        Xs[i] = st["X"]
    return S, E, Xs, zmax


def assert_comes_to_rest(integ, kp, h, *, z_tol, v_tol, drift_tol):
    """``set_down_on_a_face`` by ``integ`` in steps of h for 10 s: finite, energy monotone to
    rounding, at rest at the equilibrium penetration 8·|g|/(4k) (to z_tol cm, |U| and |L| below
    v_tol), no drift over the last 5 s (drift_tol cm), after sliding; the face never left the ground."""
    d_eq = 8 * abs(kp.g) / (4 * kp.k)
    S, E, Xs, zmax = set_down_on_a_face(integ, kp, h)
    n = len(E)
    assert np.all(np.isfinite(E))
    assert np.max(np.diff(E)) <= 1e-12 * abs(E[0])  # monotone to rounding
    st = S[0]
    assert abs(st["X"][2] - (1 - d_eq)) < z_tol
    assert np.abs(st["U"]).max() < v_tol and np.abs(st["L"]).max() < v_tol
    assert np.abs(Xs[-1] - Xs[n // 2]).max() < drift_tol  # no drift over the last 5 s
    assert np.abs(Xs[-1, :2]).max() > 1e-3  # it did slide before it stopped
    assert zmax[[0, 2, 4, 6]].max() < 0  # the face never left the ground


def test_dop853_resting_die_is_stiff_stable():
    """A die set down on a face (too deep, sliding, spinning) for 10 s of simulated time,
    in macro steps of 100 ms: ω·dt = 50 (ω = √(4k/8) on a face), eight times DOP853's
    stability bound and 17 times RK4's.  The error control keeps every sub-step stable: the energy never rises
    (beyond rounding), the die comes to rest at the equilibrium penetration
    8·|g| / (4k), and once at rest it does not drift."""
    kp = kparams(integrator="contact-dop853", tol=1e-8, friction="per-node", clamp_normal=True, energy="rigid", v_reg_cm_s=10.0)
    h = 0.1
    assert math.sqrt(kp.k / 2.0) * h > 8 * INTEGRATORS["contact-dop853"].stability_bound
    assert_comes_to_rest("contact-dop853", kp, h, z_tol=1e-8, v_tol=1e-6, drift_tol=1e-8)


# -- contact-tsit5: Tsitouras' 5(4) pair on the quaternion state -------------------------------------


def butcher_conditions(A, b):
    """Residuals of the 17 order conditions of orders 1–5 (Butcher's rooted trees), c = A·1."""
    c = A.sum(axis=1)
    Ac, Ac2, Ac3 = A @ c, A @ c**2, A @ c**3
    AAc = A @ Ac
    return {
        1: [b.sum() - 1],
        2: [b @ c - 1 / 2],
        3: [b @ c**2 - 1 / 3, b @ Ac - 1 / 6],
        4: [b @ c**3 - 1 / 4, b @ (c * Ac) - 1 / 8, b @ Ac2 - 1 / 12, b @ AAc - 1 / 24],
        5: [
            b @ c**4 - 1 / 5, b @ (c**2 * Ac) - 1 / 10, b @ (c * Ac2) - 1 / 15, b @ (c * AAc) - 1 / 30,
            b @ (Ac * Ac) - 1 / 20, b @ Ac3 - 1 / 20, b @ (A @ (c * Ac)) - 1 / 40, b @ (A @ Ac2) - 1 / 60,
            b @ (A @ AAc) - 1 / 120,
        ],
    }


def test_tsit5_tableau_is_a_5_4_pair():
    """Tsit5's coefficients: the solution satisfies all 17 order conditions up to order 5,
    the embedded one (b̂ = b − E on the seven stages, the seventh the derivative at the new
    state: first same as last) all 8 up to order 4 and not those of order 5.  Its stability
    function reaches −3.51 on the real axis (the friction bound ``FRICTION_THETA`` sits
    inside) and the table's ``stability_bound`` is where one step amplifies an undamped
    oscillation by 1e-3."""
    from dicetrace.core.methods import tsit5 as contact_tsit5
    from dicetrace.core.methods.erk import TSIT5_A, TSIT5_B, TSIT5_E

    A, b, E = TSIT5_A, TSIT5_B, TSIT5_E
    assert A.shape == (6, 6) and b.shape == (6,) and E.shape == (7,)
    assert np.all(np.triu(A) == 0)  # explicit
    for order, res in butcher_conditions(A, b).items():  # to the rounding of the tabulated digits
        assert np.abs(res).max() < 3e-14, (order, res)
    A7 = np.zeros((7, 7))
    A7[:6, :6] = A
    A7[6, :6] = b  # the seventh stage: the derivative at the new state
    bhat = np.append(b, 0.0) - E
    cond = butcher_conditions(A7, bhat)
    for order in (1, 2, 3, 4):
        assert np.abs(cond[order]).max() < 3e-14, (order, cond[order])
    assert np.abs(cond[5]).max() > 1e-4  # an order-4 estimate, not another order-5 solution

    def R(z):
        return 1 + z * b @ np.linalg.solve(np.eye(6) - z * A, np.ones(6))

    assert abs(R(-3.50)) <= 1 < abs(R(-3.52))
    assert contact_tsit5.FRICTION_THETA < 3.50
    bound = INTEGRATORS["contact-tsit5"].stability_bound
    assert abs(R(1j * (bound - 0.01))) < 1 + 1e-3 < abs(R(1j * (bound + 0.01)))


def test_tsit5_smooth_contact_order_5():
    """The smooth sliding, spinning, rocking contact of ``test_smooth_contact_order`` with
    fixed Tsit5 steps: the error against contact-substep at T/2¹⁰ sub-steps falls at order 5
    (local slopes 5.4, 4.9 measured; at longer steps 6.3–7.3: Tsitouras chose the pair to
    make its order-6 error terms small, so the h⁵ term takes over only at short steps)."""
    hs = SMOOTH_T / 2.0 ** np.arange(6, 9)
    errs = smooth_contact_errors("contact-tsit5", fixed_substeps("contact-tsit5", **SMOOTH), hs)
    s = slopes(hs, errs)
    assert np.all(s > 4.6) and np.all(s < 5.7), (errs, s)
    assert errs[-1] < 2e-10


def test_tsit5_undamped_bounce_converges():
    """The undamped flat bounce with fixed Tsit5 steps: exit/entry speed ratio → 1 at order 5."""
    hs = T_CONTACT / 2.0 ** np.arange(4, 8)
    ratio_err = bounce_ratio_errors("contact-tsit5", fixed_substeps("contact-tsit5", k=K_BOUNCE, gamma=0.0, mu=0.0, g=0.0), hs)
    s = slopes(hs, ratio_err)
    assert np.all(s > 4.6) and np.all(s < 5.5), (ratio_err, s)  # 4.8, 5.0, 5.0 measured
    assert ratio_err[-1] < 1e-11


def test_tsit5_resting_die_is_stiff_stable():
    """A die set down on a face (too deep, sliding, spinning) for 10 s of simulated time, in
    macro steps of 100 ms: ω·dt = 50 (ω = √(4k/8) on a face), 39 times Tsit5's bound.  The
    error control keeps every sub-step stable: the energy never rises (beyond rounding), the
    die comes to rest at the equilibrium penetration 8·|g|/(4k), and at rest it does not drift.

    Unlike DOP853 (stable on the imaginary axis up to 5.96, which damps the ringing to
    rounding), Tsit5 amplifies an undamped oscillation by 1 + O((ωh)⁶) per step, and the
    controller holds the face's ringing at the level of the tolerance instead: at tol = 1e-9
    the rest height is off by 8e-10 cm and the die vibrates at ~3e-6 cm/s (at 1e-8: 2e-8 cm,
    3e-5 cm/s), far below anything the stop test or the outcome sees."""
    tol = 1e-9
    kp = kparams(integrator="contact-tsit5", tol=tol, friction="per-node", clamp_normal=True, energy="rigid", v_reg_cm_s=10.0)
    h = 0.1
    assert math.sqrt(kp.k / 2.0) * h > 30 * INTEGRATORS["contact-tsit5"].stability_bound
    assert_comes_to_rest("contact-tsit5", kp, h, z_tol=3 * tol, v_tol=1e-5, drift_tol=30 * tol)


def test_tsit5_sub_steps_may_span_several_steps():
    """With dense output a sub-step is bounded by ``DENSE_CAP``·dt, not dt.  A die set down on a
    face, sliding, then rocking, at a loose tolerance in steps of 1 ms for 0.5 s: Tsit5 covers
    the 0.5 s with fewer accepted sub-steps than steps (the step ends between are interpolated;
    at a bound of dt it would need one a step at least), contact-adaptive (no dense output)
    with more.  Both end where a tolerance of 1e-9 takes the die."""
    from dicetrace.core.contact_driver import DENSE_CAP
    from dicetrace.core.state import SUBSTEP_CAUSES

    assert DENSE_CAP > 1
    n = 500
    accepted = SUBSTEP_CAUSES.index("rejected")  # the causes before it end accepted sub-steps
    def slide(integ, tol):
        kp = kparams(integrator=integ, tol=tol, friction="per-node", clamp_normal=True, energy="rigid",
                     v_reg_cm_s=10.0)
        d_eq = 8 * abs(kp.g) / (4 * kp.k)
        S = state(kp, [0, 0, 1 - d_eq], [30.0, 0, 0], [0, 0, 0])
        assert driver(integ)(kp, 1e-3, n, S, np.full(8, np.inf), np.full(8, -np.inf))
        return S[0]["substeps"][:accepted].sum(), S[0]["X"].copy(), S[0]["U"].copy()

    _, X_ref, U_ref = slide("contact-tsit5", 1e-9)
    for integ in ("contact-tsit5", "contact-adaptive"):
        subs, X, U = slide(integ, 1e-5)
        if integ == "contact-tsit5":
            assert subs < 0.8 * n, subs
        else:
            assert subs >= n, subs
        assert np.abs(X - X_ref).max() < 5e-4 and np.abs(U - U_ref).max() < 0.05, (integ, X - X_ref, U - U_ref)


def tsit5_dense_errors(hs, theta):
    """Errors of Tsit5's continuous extension at θ·h into one sub-step of the smooth contact.

    One Tsit5 sub-step of length h from the start of the smooth contact, its error estimate
    (which evaluates the seventh stage, the derivative at the new state), then
    ``erk.dense_keep`` and ``erk.dense_state`` at θ: the state there against contact-substep
    at SMOOTH_T/2¹⁰ sub-steps to the same time.  Also returns, per h, how far θ = 1 is from
    the sub-step's own result (b_i(1) = B_i, to the rounding of the tabulated digits)."""
    from dicetrace.core.forces import step_wrench, wrench_at
    from dicetrace.core.methods.erk import dense_keep, dense_state, tsit5_error, tsit5_substep
    from dicetrace.core.schemes import contact_tsit5
    from dicetrace.core.state import begin_substeps

    kp = kparams(integrator="contact-tsit5", **SMOOTH)
    d_eq = 8 * 980.0 / (4 * kp.k)
    X0, U0, L0 = [0, 0, 1 - d_eq], [3.0, -2.0, 0.3], [0.8, -0.6, 12.0]
    errs, ends = [], []
    for h in hs:
        Xr, Ur, Lr, offr, *_ = run("contact-substep", kp, SMOOTH_T / 2**10, theta * h, X0, U0, L0)
        S = state(kp, X0, U0, L0)
        Wk = new_work(contact_tsit5.WORK)
        st, wk = S[0], Wk[0]
        contact, _ = eval_forces(st, kp)
        begin_substeps(st, wk)
        tsit5_substep(st, wk, kp, h, *step_wrench(st, contact, True))
        n = Wk.copy()[0]
        I = kp.inertia
        _, *g = wrench_at(n["new_X"][2], *n["new_U"], *(n["new_L"] / I), n["new_off"], kp, st["F"], st["uk"], st["z"], st["P"])
        tsit5_error(st, wk, kp, h, *g)
        dense_keep(st, wk, h)
        dense_state(st, wk, kp, 1.0)
        ends.append(max(np.abs(st["X"] - n["new_X"]).max(), np.abs(st["off"] - n["new_off"]).max()))
        dense_state(st, wk, kp, theta)
        errs.append(max(np.abs(st["X"] - Xr).max(), np.abs(st["U"] - Ur).max() / 100, np.abs(st["L"] - Lr).max() / 100,
                        np.abs(st["off"] - offr).max()))
        W = st["W"] * I
        assert np.array_equal(W, st["L"]) or np.allclose(W, st["L"], rtol=1e-15, atol=0)
    return np.array(errs), np.array(ends)


def test_tsit5_dense_output_is_order_4():
    """Tsit5's continuous extension (the state at a step end inside a sub-step): its error at
    θ = 1/2 of one sub-step of the smooth contact falls as h⁵ (an order-4 interpolant's local
    error; measured slopes 5.0, 5.0), and at θ = 1 it is the sub-step's own result."""
    hs = SMOOTH_T / 2.0 ** np.arange(5, 9)
    errs, ends = tsit5_dense_errors(hs, 0.5)
    s = slopes(hs, errs)
    assert np.all(s[-2:] > 4.6) and np.all(s < 6.5), (errs, s)
    assert errs[-1] < 1e-10
    assert ends.max() < 1e-14, ends


def test_tsit5_step_ends_inside_substeps_follow_the_trajectory():
    """contact-tsit5 lets its last sub-step run past the end of a macro step and interpolates
    the state at the step end: on a whole throw at tol 1e-10 no sub-step ends at a step end,
    and the recorded state at every step end of the first 0.3 s (a dozen impacts) is within
    1e-7 cm (positions, offsets) and 1e-5 cm/s (velocities) of contact-dop853 at tol 1e-12,
    and so are the contact forces at the step ends in contact."""
    from dicetrace.ics import seed_slice
    from dicetrace.simulate import Record, simulate

    ic = seed_slice(1.65, 3.9) * np.array([1, 1, 1, -1, -1, -1])
    rec = Record(states=True, energy=False, forces=True)
    a = simulate(ic, preset="physical", integrator="contact-tsit5", tol=1e-10, t_max_s=0.3, record=rec)
    b = simulate(ic, preset="physical", integrator="contact-dop853", tol=1e-12, t_max_s=0.3, record=rec)
    assert a.substeps["end"] == 0 and a.substeps["error"] > 300
    ta, tb = a.trace, b.trace
    n = min(len(ta.t_s), len(tb.t_s))
    assert n == 301
    assert np.abs(ta.cm_pos[:n] - tb.cm_pos[:n]).max() < 1e-7
    assert np.abs(ta.node_offsets[:n] - tb.node_offsets[:n]).max() < 1e-7
    assert np.abs(ta.cm_vel[:n] - tb.cm_vel[:n]).max() < 1e-5
    assert (np.abs(ta.forces[:n]) > 0).any(axis=(1, 2)).sum() >= 8  # in contact at step ends
    assert np.abs(ta.forces[:n] - tb.forces[:n]).max() < 1e-5 * np.abs(tb.forces[:n]).max()


# -- the high-order scheme's shortcuts are the full computation, bit for bit --------------------


@pytest.mark.parametrize("friction", ["per-node", "spectral"])
def test_stage_wrench_is_rotation_then_wrench_at(friction):
    """``erk.stage_wrench`` (third row of R for every node, the rest only below the ground)
    gives the force sum and torque of ``quat_rotate`` + ``wrench_at`` exactly, on tilted,
    moving dice with 0 to 4 nodes in the ground, for both friction laws."""
    from dicetrace.core.forces import wrench_at
    from dicetrace.core.methods.erk import quat_rotate, stage_wrench

    kp = kparams(friction=friction, clamp_normal=friction == "per-node", v_reg_cm_s=10.0)
    off = np.zeros((8, 3))
    init_offsets(kp.half_side_cm, off)
    rng = np.random.default_rng(11)
    scratch = [np.zeros((8, 3)), np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8)]
    below_counts = set()
    for _ in range(400):
        q = rng.normal(size=4) * rng.uniform(0.5, 2.0)  # any norm: both sides read q/|q|
        y = np.concatenate([[0.1, -0.2], [rng.uniform(0.9, 1.8)], rng.normal(0, 80, 3), rng.normal(0, 200, 3), q])
        I = kp.inertia
        got = stage_wrench(y, off, kp, *scratch, y[6] / I, y[7] / I, y[8] / I)
        offs = np.zeros((8, 3))
        quat_rotate(q[0], q[1], q[2], q[3], off, offs)
        below_counts.add(int(np.sum(y[2] + offs[:, 2] < 0)))
        F, uk, z, P = np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8)
        _, *want = wrench_at(y[2], y[3], y[4], y[5], y[6] / I, y[7] / I, y[8] / I, offs, kp, F, uk, z, P)
        assert got == tuple(want)
    assert {0, 1, 2} <= below_counts and max(below_counts) >= 3


def _eval_into(S, kp):
    return eval_forces(S[0], kp)


#: ``eval_forces`` compiled on its own, as every kernel is (strict arithmetic).
_STRICT_EVAL = jit(_eval_into)


@pytest.mark.parametrize("integ", ["contact-dop853", "contact-tsit5"])
@pytest.mark.parametrize("preset", ["physical", "seed"])
def test_contact_step_ends_with_the_forces_of_its_state(preset, integ):
    """A contact step reuses forces it already has (the previous step's end, its last
    sub-step's error evaluation, the forces kept at contact-tsit5's front) instead of
    evaluating them again: after every step of a throw, the forces, heights and contact mask
    it leaves are exactly what ``eval_forces`` computes afresh at its state."""
    cfg = make_config(preset, integrator=integ, tol=1e-6)
    kp = cfg.kernel_params()
    ic = np.array([80.0, -40.0, 0.0, 300.0, -500.0, 150.0])
    S = state(kp, [0.0, 0.0, 2.0], ic[:3], ic[3:] if preset == "seed" else -ic[3:], cfg.initial_offsets())
    step = step_of(INTEGRATORS[integ])
    Wk = new_work(scheme_module(INTEGRATORS[integ]).WORK)
    contact, mask = eval_forces(S[0], kp)
    in_contact = 0
    for _ in range(600):
        contact, mask = step(S[0], Wk[0], kp, 1e-3, contact)
        fresh = S.copy()
        want = _STRICT_EVAL(fresh, kp)
        assert (contact, mask) == want
        for name in ("F", "P", "z") + (("uk",) if contact else ()):
            assert np.array_equal(S[0][name], fresh[0][name], equal_nan=True), name
        in_contact += contact
    assert in_contact > 50


def test_hermite_root_is_the_first_crossing():
    """``contacts.hermite_root`` (where a sub-step is cut): on random cubic Hermite
    height data it returns a root of the cubic to rounding (one of numpy's roots of the same
    cubic) in the first eighth of (0, 1) where the cubic changes sign, and −1 exactly when it
    changes sign in none."""
    from dicetrace.core.contacts import hermite_root

    rng = np.random.default_rng(5)
    found = 0
    for _ in range(3000):
        z0, z1 = rng.normal(size=2)
        v0, v1 = rng.normal(size=2) * 3
        h = rng.uniform(0.1, 2.0)
        c = [z0, h * v0, 3 * (z1 - z0) - 2 * h * v0 - h * v1, 2 * (z0 - z1) + h * v0 + h * v1]
        r = np.roots(c[::-1])
        r = np.sort(r[np.abs(r.imag) < 1e-12].real)
        r = r[(r > 0) & (r < 1)]
        grid = np.polynomial.polynomial.polyval(np.arange(9) / 8, c)
        changes = np.nonzero(np.diff(np.sign(grid)))[0]
        th = hermite_root(z0, v0, z1, v1, h)
        if len(changes) == 0:
            assert th == -1.0
            continue
        found += 1
        lo = changes[0] / 8
        assert lo <= th <= lo + 1 / 8
        assert abs(np.polynomial.polynomial.polyval(th, c)) < 1e-13 * max(1.0, np.abs(c).max())
        assert np.isclose(th, r[(r >= lo - 1e-12) & (r <= lo + 1 / 8 + 1e-12)]).any()
    assert found > 1000
