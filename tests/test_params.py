"""dicetrace.params: validated presets and numerics, dt = auto, the L sign convention, the door to the kernels."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from dicetrace.ics import seed_slice
from dicetrace.params import (
    INTEGRATORS,
    KERNEL_L_CONVENTION,
    NODE_SIGNS,
    TOL_GROWTH_MAX,
    TOL_MIN,
    Config,
    Numerics,
    Preset,
    convert_l,
    get_integrator,
    get_preset,
    make_config,
    ConfigError,
    resolve_config,
)
from dicetrace.stepsize import AUTO_DT_FE_GAIN, AUTO_DT_MAX_S, AUTO_DT_MAX_STEPS, AUTO_DT_SAFETY, auto_dt, impact_speed_cm_s, stiff_rates

NUMERIC_PRESET_FIELDS = ("k", "gamma", "mu", "g", "half_side_cm", "z0_cm", "v_reg_cm_s")


# -- Preset ------------------------------------------------------------------------------------


@pytest.mark.parametrize("field", NUMERIC_PRESET_FIELDS)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, "1", None, True, [1.0]], ids=repr)
def test_preset_refuses_a_non_number_naming_the_field(field, value):
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        Preset(**{field: value})


@pytest.mark.parametrize(
    "changes, field",
    [
        pytest.param({"k": 0.0}, "k", id="k=0"),
        pytest.param({"k": -5e5}, "k", id="k<0"),
        pytest.param({"gamma": -0.001}, "gamma", id="gamma<0"),
        pytest.param({"mu": -0.1}, "mu", id="mu<0"),
        pytest.param({"half_side_cm": 0.0}, "half_side_cm", id="half=0"),
        pytest.param({"v_reg_cm_s": 0.0}, "v_reg_cm_s", id="v_reg=0"),
        pytest.param({"friction": "coulomb"}, "friction", id="friction"),
        pytest.param({"energy": "kinetic"}, "energy", id="energy"),
        pytest.param({"l_convention": "left-handed"}, "l_convention", id="l_convention"),
        pytest.param({"integrator": "magic"}, "integrator", id="integrator"),
        pytest.param({"z0_cm": -5.0}, "z0_cm", id="z0 below the ground"),
        pytest.param({"clamp_normal": "no"}, "clamp_normal", id="clamp_normal='no'"),
    ],
)
def test_preset_refuses_a_bad_value_naming_the_field(changes, field):
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        Preset(**changes)


def test_preset_accepts_numpy_floats_and_is_frozen():
    p = Preset(k=np.float64(1e6), mu=0)
    assert p.k == 1e6 and p.mu == 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.k = 1.0  # a preset shared by many configs cannot change under them
    assert get_preset("seed").with_(gamma=0.01).gamma == 0.01 and get_preset("seed").gamma == 0.005


def test_preset_and_numerics_accept_any_numpy_real():
    Preset(k=np.int64(500000), mu=np.float32(1.2))
    Numerics(dt_s=np.float32(1e-3), tol=np.float32(1e-7))


def test_get_preset_and_get_integrator_name_the_choices():
    with pytest.raises(ValueError, match="unknown preset 'moon'.*seed, physical"):
        get_preset("moon")
    with pytest.raises(ValueError, match="unknown integrator 'magic'.*semi-implicit-euler.*contact-adaptive"):
        get_integrator("magic")
    with pytest.raises(ValueError, match="unknown integrator"):
        get_integrator(["rk4"])  # unhashable: still a ValueError, not a TypeError


def test_a_removed_integrator_is_refused_saying_so():
    """contact-rosenbrock (kernel id 7) was removed: its name gets one line that says so and names the
    choices; its id is free, not reused (the ids stored in scans and results keep their meaning)."""
    with pytest.raises(ValueError) as exc:
        get_integrator("contact-rosenbrock")
    (line,) = str(exc.value).splitlines()
    assert "'contact-rosenbrock'" in line and "removed" in line and "contact-tsit5" in line
    with pytest.raises(ValueError, match="'contact-rosenbrock': it was removed"):
        make_config("physical", integrator="contact-rosenbrock")
    assert 7 not in {s.kernel_id for s in INTEGRATORS.values()}
    assert INTEGRATORS["contact-tsit5"].kernel_id == 8 and INTEGRATORS["contact-dop853"].kernel_id == 6


# -- Numerics ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes, words",
    [
        pytest.param({"dt_s": True}, "time step dt", id="dt=True"),
        pytest.param({"dt_s": 0.0}, "time step dt", id="dt=0"),
        pytest.param({"dt_s": -1e-3}, "time step dt", id="dt<0"),
        pytest.param({"dt_s": math.nan}, "time step dt", id="dt=nan"),
        pytest.param({"dt_s": math.inf}, "time step dt", id="dt=inf"),
        pytest.param({"dt_s": "1e-3"}, "time step dt", id="dt='1e-3'"),
        pytest.param({"t_max_s": True}, "time cap t_max", id="t_max=True"),
        pytest.param({"t_max_s": 0.0}, "time cap t_max", id="t_max=0"),
        pytest.param({"t_max_s": math.inf}, "time cap t_max", id="t_max=inf"),
        pytest.param({"t_max_s": 1e12, "dt_s": 1e-3}, "time cap / dt", id="too many steps"),
        pytest.param({"substeps": 0}, "substeps", id="substeps=0"),
        pytest.param({"substeps": 2.5}, "substeps", id="substeps=2.5"),
        pytest.param({"substeps": True}, "substeps", id="substeps=True"),
        pytest.param({"substeps": "x"}, "substeps", id="substeps='x'"),
        pytest.param({"substeps": math.nan}, "substeps", id="substeps=nan"),
        pytest.param({"tol": True}, "tolerance tol", id="tol=True"),
        pytest.param({"tol": 0.0}, "tolerance tol", id="tol=0"),
        pytest.param({"tol": 1.0}, "tolerance tol", id="tol=1"),
        pytest.param({"tol": TOL_MIN / 2}, "tolerance tol", id="tol<TOL_MIN"),
        pytest.param({"tol": math.nan}, "tolerance tol", id="tol=nan"),
        pytest.param({"tol_growth": -1.0}, "tolerance growth tol_growth", id="tol_growth<0"),
        pytest.param({"tol_growth": math.inf}, "tolerance growth tol_growth", id="tol_growth=inf"),
        pytest.param({"tol_growth": TOL_GROWTH_MAX * 2}, "tolerance growth tol_growth", id="tol_growth>max"),
        pytest.param({"tol_growth": True}, "tolerance growth tol_growth", id="tol_growth=True"),
        pytest.param({"integrator": "magic"}, "unknown integrator 'magic'", id="integrator"),
        pytest.param({"integrator": "contact-rosenbrock"}, "'contact-rosenbrock': it was removed", id="removed integrator"),
    ],
)
def test_numerics_refuses_a_bad_value_naming_the_field(changes, words):
    with pytest.raises(ValueError, match=words.replace("/", r"\/")):
        Numerics(**changes)


def test_numerics_edges_that_are_valid():
    assert Numerics(tol=TOL_MIN).tol == TOL_MIN
    assert Numerics(tol=np.nextafter(1.0, 0.0)).tol < 1
    assert Numerics(substeps=1).substeps == 1
    assert Numerics(dt_s=1, t_max_s=1).max_steps == 1
    # max_steps covers the cap without an extra step where t_max/dt is a whole number in decimal
    assert Numerics(dt_s=0.001, t_max_s=0.3).max_steps == 300
    assert Numerics(dt_s=0.0007, t_max_s=0.3).max_steps == 429  # 428.57…: rounded up


# -- dt = auto --------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", INTEGRATORS)
@pytest.mark.parametrize("preset", ["seed", "physical"])
@pytest.mark.parametrize("v_impact", [0.0, 300.0, 3000.0])
def test_auto_dt_keeps_each_integrator_within_its_stability_bound(name, preset, v_impact):
    """λ·h at AUTO_DT_SAFETY of the scheme's bound (h the sub-step for contact-substep), as large as that allows;
    the error-controlled schemes the longest step (their error control keeps their sub-steps stable)."""
    spec = INTEGRATORS[name]
    p = get_preset(preset)
    dt = auto_dt(p, name, v_impact_cm_s=v_impact, t_max_s=1.0)
    lam, _ = stiff_rates(p, v_impact)
    h = dt / Numerics.substeps if spec.substepped else dt
    assert 0 < dt <= AUTO_DT_MAX_S
    if spec.adaptive:  # error control keeps the sub-steps stable: dt is the stop test's cadence
        assert dt == AUTO_DT_MAX_S
    elif spec.stability_bound > 0:
        assert lam * h <= AUTO_DT_SAFETY * spec.stability_bound * (1 + 1e-12)
        assert dt == AUTO_DT_MAX_S or lam * h >= AUTO_DT_SAFETY * spec.stability_bound * (1 - 1e-12)
    else:  # forward Euler amplifies every oscillation: its energy gain over one contact (π/λ) stays small
        assert math.exp(math.pi * lam * dt / 2) - 1 <= AUTO_DT_FE_GAIN * 1.01
    # a harder impact never gets a longer step
    assert auto_dt(p, name, v_impact_cm_s=2 * v_impact + 100, t_max_s=1.0) <= dt


@pytest.mark.parametrize("name", INTEGRATORS)
def test_auto_dt_runs_a_stiff_ground_without_failing(name):
    """k = 5·10⁶ (ω·1 ms = 2.2, beyond the explicit schemes' bound): dt auto stays stable; the program's 1 ms
    step blows up with the Euler schemes (so the automatic choice is what saves them)."""
    from dicetrace.simulate import Record, simulate

    ic = seed_slice(1.65, 3.9)
    p = get_preset("seed").with_(k=5e6)
    cfg = make_config(p, integrator=name, dt_s="auto", t_max_s=0.5, v_impact_cm_s=impact_speed_cm_s(ic, p))
    r = simulate(ic, config=cfg, record=Record(states=False, energy=True))
    assert not r.status.failed, (name, cfg.numerics.dt_s, r.status)
    e = r.trace.energy["total"]
    assert e.max() <= e[0] * 1.01
    assert r.contact_sets.size > 3  # it did hit the ground
    if name in ("semi-implicit-euler", "forward-euler"):
        fixed = simulate(ic, config=make_config(p, integrator=name, dt_s=1e-3, t_max_s=0.5))
        assert fixed.status.failed


def test_auto_dt_refuses_in_one_line_when_no_step_fits():
    with pytest.raises(ValueError, match=r"dt auto: forward-euler needs dt <= .*budget") as exc:
        auto_dt(get_preset("seed"), "forward-euler", t_max_s=AUTO_DT_MAX_STEPS)
    assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="'auto'"):
        make_config("seed", dt_s="fast")
    assert make_config("seed", dt_s=" AUTO ").numerics.dt_s == auto_dt(get_preset("seed"), "semi-implicit-euler")


def test_impact_speed_bounds_every_node_at_the_first_impact():
    from dicetrace.simulate import Record, simulate

    ics = np.concatenate([seed_slice([1.65, 0.3, 12.0], [3.9, 7.1, 2.0]), [[0.0, 0.0, -400.0, 300.0, -50.0, 20.0]]])
    p = get_preset("seed")
    for ic in ics:
        r = simulate(ic, record=Record(states=True, energy=False))
        first = int(r.contact_steps[1])
        vel = np.diff(r.trace.node_pos[first - 1 : first + 1], axis=0)[0] / r.dt_s  # node velocities before impact
        assert np.linalg.norm(vel, axis=1).max() <= impact_speed_cm_s(ic, p)
    assert impact_speed_cm_s(ics, p) == max(impact_speed_cm_s(ic, p) for ic in ics)
    # either sign convention of L: the same bound
    assert impact_speed_cm_s(convert_l(ics, "program", "physical"), p) == impact_speed_cm_s(ics, p)


# -- the L sign convention ----------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(6,), (5, 6), (2, 3, 6)])
def test_convert_l_round_trips_bit_for_bit_and_leaves_u_alone(shape):
    rng = np.random.default_rng(4)
    ics = rng.normal(scale=100.0, size=shape)
    ics.flat[3] = 0.0  # +0.0 becomes −0.0 and back
    before = ics.copy()
    phys = convert_l(ics, "program", "physical")
    np.testing.assert_array_equal(ics, before)  # the input is not modified
    assert phys.shape == shape and phys.dtype == np.float64
    np.testing.assert_array_equal(phys[..., :3], ics[..., :3])
    np.testing.assert_array_equal(phys[..., 3:], -ics[..., 3:])
    assert np.signbit(phys.flat[3])
    back = convert_l(phys, "physical", "program")
    assert np.array_equal(back.view(np.uint64), ics.view(np.uint64))  # bit for bit, signed zeros included
    assert convert_l(ics, "physical", "physical") is ics  # no conversion, no copy
    assert convert_l(ics, "program", "program") is ics


def test_convert_l_names_a_bad_convention():
    with pytest.raises(ValueError, match="L convention must be one of program, physical, got 'left'"):
        convert_l(np.zeros(6), "left", "program")
    with pytest.raises(ValueError, match="'physics'"):
        convert_l(np.zeros(6), "program", "physics")


def test_kernel_inputs_flip_L_exactly_for_the_physical_convention_only():
    ics = seed_slice([1.65, 0.0], [3.9, 0.0])  # the second has L = (0, 100, 0) with zeros: signs must flip too
    seed, phys = make_config("seed"), make_config("physical")
    assert KERNEL_L_CONVENTION == seed.preset.l_convention == "program" and phys.preset.l_convention == "physical"
    k_seed = seed.kernel_inputs(ics)
    assert k_seed.ics.dtype == np.float64 and k_seed.ics.flags.c_contiguous
    assert np.array_equal(k_seed.ics.view(np.uint64), ics.view(np.uint64))  # unchanged
    k_phys = phys.kernel_inputs(ics)
    np.testing.assert_array_equal(k_phys.ics[:, :3], ics[:, :3])
    assert np.array_equal(k_phys.ics[:, 3:].view(np.uint64), (-ics[:, 3:]).view(np.uint64))  # exactly −L
    # an explicit convention wins over the preset's
    np.testing.assert_array_equal(phys.kernel_inputs(ics, l_convention="program").ics, ics)
    np.testing.assert_array_equal(seed.kernel_inputs(ics, l_convention="physical").ics, k_phys.ics)
    # one IC, a non-contiguous input: still a C-contiguous float64 row
    one = seed.kernel_inputs(np.asfortranarray(ics)[0])
    assert one.ics.shape == (6,) and one.ics.flags.c_contiguous
    # the rest of the door: this config's offsets, parameters and kernel id
    assert k_phys.integrator_id == INTEGRATORS["contact-tsit5"].kernel_id
    assert k_phys.params == phys.kernel_params()
    np.testing.assert_array_equal(k_phys.off0, phys.initial_offsets())


def test_initial_offsets_number_the_nodes_and_turn_with_the_orientation():
    cfg = make_config("seed", half_side_cm=1.5)
    off = cfg.initial_offsets()
    # node k+1 = 1 + 4[x>0] + 2[y>0] + [z>0]
    for k in range(8):
        assert 1 + 4 * (off[k, 0] > 0) + 2 * (off[k, 1] > 0) + (off[k, 2] > 0) == k + 1
    assert np.all(np.abs(off) == 1.5) and np.array_equal(off, NODE_SIGNS * 1.5)
    c, s = math.cos(0.3), math.sin(0.3)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(cfg.initial_offsets(rot), off @ rot.T, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="not a rotation"):
        cfg.initial_offsets(np.diag([1.0, 1.0, -1.0]))  # a mirror
    with pytest.raises(ValueError, match="not a rotation"):
        cfg.initial_offsets(2 * np.eye(3))
    with pytest.raises(ValueError, match="3×3"):
        cfg.initial_offsets(np.eye(2))


# -- Config and its construction ----------------------------------------------------------------------


def test_config_as_dict_rebuilds_the_same_config():
    """File metadata (as_dict) is enough to rebuild the configuration a scan or a recording used."""
    for cfg in (make_config("seed"), make_config("physical", tol=1e-9, gamma=0.01), make_config("seed", integrator="rk4", dt_s="auto"),
                make_config("physical", tol=2e-8, tol_growth=10.0)):
        d = cfg.as_dict()
        assert Config(preset=Preset(**d["preset"]), numerics=Numerics(**d["numerics"])) == cfg


def test_tol_reaches_only_the_adaptive_kernel():
    """tol changes contact-adaptive's result, and nothing else's (where it is ignored, make_config says so)."""
    from dicetrace.simulate import Record, simulate

    ic = seed_slice(1.65, 3.9)

    def run(integrator, tol):
        r = simulate(ic, preset="physical", integrator=integrator, tol=tol, t_max_s=0.4, record=Record(states=True, energy=False))
        return r.trace.node_pos[-1].tobytes()

    with pytest.warns(UserWarning, match="no effect on contact-substep"):
        assert run("contact-substep", 1e-3) == run("contact-substep", 1e-10)
    assert run("contact-adaptive", 1e-3) != run("contact-adaptive", 1e-10)


def test_tol_growth_reaches_only_the_adaptive_kernels():
    with pytest.warns(UserWarning, match="tol_growth .*no effect on rk4"):
        assert make_config("physical", integrator="rk4", tol_growth=10.0).kernel_params().tol_growth == 0.0
    assert make_config("physical", tol_growth=10.0).kernel_params().tol_growth == 10.0
    assert make_config("seed", integrator="contact-tsit5").kernel_params().tol_growth == 0.0  # off by default
    # a scan written before the field existed still reads: its numerics lack it
    cfg = make_config("seed", integrator="contact-tsit5")
    d = cfg.as_dict()
    del d["numerics"]["tol_growth"]
    assert Config(preset=Preset(**d["preset"]), numerics=Numerics(**d["numerics"])) == cfg


@pytest.mark.parametrize("integrator", ["contact-tsit5", "contact-adaptive", "contact-dop853"])
def test_physical_schedule_is_the_default_of_every_error_controlled_integrator(integrator):
    num = make_config("physical", integrator=integrator).numerics
    assert (num.tol, num.tol_growth) == (2e-8, 10.0)
    assert make_config("physical", integrator=integrator).kernel_params().tol_growth == 10.0
    # one of the two given: the schedule is off, the other keeps Numerics' default
    num = make_config("physical", integrator=integrator, tol=1e-6).numerics
    assert (num.tol, num.tol_growth) == (1e-6, 0.0)
    num = make_config("physical", integrator=integrator, tol_growth=5.0).numerics
    assert (num.tol, num.tol_growth) == (Numerics.tol, 5.0)
    # a preset derived from physical keeps its schedule; seed has none
    assert make_config("physical", integrator=integrator, v_reg_cm_s=3.0).numerics.tol_growth == 10.0
    num = make_config("seed", integrator=integrator).numerics
    assert (num.tol, num.tol_growth) == (Numerics.tol, Numerics.tol_growth) == (1e-7, 0.0)


def test_physical_schedule_never_reaches_a_fixed_step_integrator():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing the caller gave, nothing to warn about
        num = make_config("physical", integrator="contact-substep").numerics
    assert (num.tol, num.tol_growth) == (Numerics.tol, 0.0)
    assert make_config("physical", integrator="contact-substep").kernel_params().tol == 0.0


@pytest.mark.parametrize("field, value", [("default_tol", 0.0), ("default_tol", 1.0), ("default_tol", float("nan")),
                                          ("default_tol", "1e-7"), ("default_tol_growth", -1.0),
                                          ("default_tol_growth", None), ("default_tol_growth", 1e4)])
def test_preset_schedule_is_validated(field, value):
    with pytest.raises(ValueError, match=f"preset 'physical': {field} must be"):
        get_preset("physical").with_(**{field: value})


def test_a_physical_config_written_before_the_schedule_still_reads():
    """A manifest from before the preset's schedule lacks its two fields: they read as 'none'."""
    d = make_config("physical", tol=1e-7).as_dict()
    for k in ("default_tol", "default_tol_growth"):
        del d["preset"][k]
    old = Config(preset=Preset(**d["preset"]), numerics=Numerics(**d["numerics"]))
    assert old.preset.default_tol is None and old.numerics == make_config("physical", tol=1e-7).numerics
    assert old != make_config("physical")  # resuming it with today's default is refused


def test_make_config_applies_overrides_to_the_named_preset():
    cfg = make_config("physical", gamma=0.01, integrator="rk4", dt_s=5e-4, t_max_s=2.0)
    assert cfg.preset == get_preset("physical").with_(gamma=0.01)
    assert (cfg.numerics.integrator, cfg.numerics.dt_s, cfg.numerics.t_max_s) == ("rk4", 5e-4, 2.0)
    assert make_config("physical").numerics.integrator == "contact-tsit5"  # the preset's own default
    with pytest.raises(TypeError):
        make_config("seed", gravity=-981.0)  # not a Preset field


def test_resolve_config_takes_a_config_or_options_never_both():
    cfg = make_config("physical")
    assert resolve_config(cfg) is cfg
    assert resolve_config("physical") == cfg == resolve_config(preset="physical")
    assert resolve_config(None, integrator=None, dt_s=None) == make_config("seed")  # None counts as not given
    with pytest.raises(ValueError, match=r"pass either config or dt_s, integrator, not both"):
        resolve_config(cfg, integrator="rk4", dt_s=1e-4)
    with pytest.raises(ValueError, match="preset once"):
        resolve_config("seed", preset="physical")
    with pytest.raises(TypeError, match="config must be"):
        resolve_config(42)


# -- one validator, one error ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "make, fields",
    [
        (lambda: Numerics(tol=0.0), ("tol",)),
        (lambda: Numerics(tol_growth=-1.0), ("tol_growth",)),
        (lambda: Numerics(dt_s=0.0), ("dt_s",)),
        (lambda: Numerics(integrator="magic"), ("integrator",)),
        (lambda: Numerics(dt_s=2.0, t_max_s=1.0), ("t_max_s", "dt_s")),
        (lambda: Preset(gamma=-1.0), ("gamma",)),
        (lambda: get_preset("moon"), ("preset",)),
        (lambda: make_config(integrator="magic"), ("integrator",)),
        (lambda: make_config(tol="abc"), ("tol",)),
        (lambda: make_config(dt_s="fast"), ("dt_s",)),
        (lambda: make_config(dt_s="auto", integrator="forward-euler", t_max_s=1e9), ("dt_s",)),
        (lambda: make_config(tol=1e-5, strict=True), ("tol",)),
        (lambda: resolve_config(make_config(), gamma=0.1, tol=1e-7), ("gamma", "tol")),
    ],
)
def test_every_check_raises_config_error_naming_the_field(make, fields):
    with pytest.raises(ConfigError) as exc:
        make()
    assert exc.value.fields == fields and exc.value.field == fields[0]
    assert isinstance(exc.value, ValueError) and str(exc.value) == exc.value.message


def test_make_config_reads_option_text_as_the_number_it_spells():
    """The text of a command's option gives the very configuration its number does (no second parser)."""
    text = make_config("physical", dt_s=" 0.0005 ", t_max_s="2", tol="3e-8", tol_growth="5")
    num = make_config("physical", dt_s=0.0005, t_max_s=2.0, tol=3e-8, tol_growth=5.0)
    assert text == num and text.kernel_params() == num.kernel_params()
    assert all(type(getattr(text.numerics, f)) is float for f in ("dt_s", "t_max_s", "tol", "tol_growth"))
    with pytest.raises(ConfigError, match=r"got '-0'$"):  # a refused value is shown as it was given
        make_config(dt_s="-0")
    with pytest.raises(ConfigError, match="time step dt"):
        Numerics(dt_s="1e-3")  # Numerics itself takes numbers only


def test_a_tolerance_a_fixed_step_integrator_ignores_warns_or_with_strict_is_refused():
    with pytest.warns(UserWarning, match="tol 1e-05 .*no effect on rk4"):
        make_config(integrator="rk4", tol=1e-5)
    with pytest.raises(ConfigError, match="tol_growth '10' .*no effect on rk4"):
        make_config(integrator="rk4", tol_growth="10", strict=True)
    with pytest.raises(ConfigError, match=r"\[1e-14, 1\)"):  # the range first, whatever the integrator
        make_config(integrator="rk4", tol="1e-300", strict=True)
    assert make_config("physical", tol="1e-7", strict=True).numerics.tol == 1e-7
