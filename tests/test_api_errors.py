"""The Python API refuses bad arguments with a ValueError or TypeError that names the argument.

The issue's item 10: ``scan(None)`` raised AttributeError, ``simulate(config={...})``
an AttributeError, an output under /proc a bare FileNotFoundError,
``simulate_batch(cap=-1)`` numpy's "negative dimensions"; ``make_config(g=980)``,
``dt_s=True``, ``scan(threads=0)`` and ``simulate(config=..., preset=...)`` were
accepted, and ``Grid("seed", "home", 10**10).size`` was wrong.  Each call
below must raise the named class, with the argument (or field) in the message.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from dicetrace.ics import Grid, Points, Sample, seed_slice
from dicetrace.params import Numerics, Preset, make_config, resolve_config
from dicetrace.scan import ScanDefinition, read_scan, scan
from dicetrace.scan.estimate import estimate_scan
from dicetrace.scan.runner import iter_scan
from dicetrace.simulate import CAP_GROWTH, Record, simulate, simulate_batch
from dicetrace.sinks._common import OutputError

IC = [14.08, 11.46, 9.87, 13.8, 122.8, 15.5]
G = Grid("seed", "home", 2)


def call(fn, exc, words, id):
    return pytest.param(fn, exc, words, id=id)


CALLS = [
    # the examples
    call(lambda: scan(None), TypeError, "space must be a Grid, Sample or Points", "scan(None)"),
    call(lambda: scan("home"), TypeError, "space must be", "scan('home')"),
    call(lambda: simulate(IC, config={"preset": "seed"}), TypeError, "config must be", "simulate(config=dict)"),
    call(lambda: simulate_batch([IC], config={"k": 1}), TypeError, "config must be", "simulate_batch(config=dict)"),
    call(lambda: scan(G, "/proc/x"), OutputError, "scan folder '/proc/x'", "scan(out=/proc/x)"),
    call(lambda: simulate_batch([IC], cap=-1), ValueError, "cap must be an integer >= 1, got -1", "cap=-1"),
    call(lambda: simulate_batch([IC], cap=2.0), ValueError, "cap", "cap=2.0"),
    call(lambda: make_config(g=980), ValueError, "gravity g must be <= 0", "g=980"),
    call(lambda: make_config(dt_s=True), ValueError, "time step dt", "dt_s=True"),
    call(lambda: simulate(IC, dt_s=True), ValueError, "time step dt", "simulate(dt_s=True)"),
    call(lambda: scan(G, threads=0), ValueError, "threads must be an integer >= 1", "scan(threads=0)"),
    call(lambda: simulate(IC, config=make_config(), preset="physical"), ValueError, "pass either config or preset",
         "config and preset"),
    call(lambda: simulate_batch([IC], config=make_config(), dt_s=1e-4), ValueError, "dt_s", "config and dt_s"),
    call(lambda: scan(G, config=make_config(), gamma=0.1), ValueError, "gamma", "scan(config and gamma)"),
    call(lambda: resolve_config("seed", preset="physical"), ValueError, "preset once", "preset twice"),
    # more of the same classes
    call(lambda: make_config(5), TypeError, "preset must be a preset name", "make_config(5)"),
    call(lambda: make_config(gravity=-980), TypeError, "unknown preset parameter(s) gravity", "unknown field"),
    call(lambda: make_config(z0_cm=0.5), ValueError, "z0_cm", "z0 below the ground"),
    call(lambda: make_config(clamp_normal="no"), ValueError, "clamp_normal", "clamp_normal='no'"),
    call(lambda: make_config(dt_s=2.0, t_max_s=1.0), ValueError, "longer than the time cap", "dt > t_max"),
    call(lambda: make_config(dt_s=np.float64(-1.0)), ValueError, "got -1.0", "np.float64 shown plainly"),
    call(lambda: make_config(v_impact_cm_s=-1.0), ValueError, "v_impact_cm_s", "v_impact < 0"),
    call(lambda: Numerics(substeps=True), ValueError, "substeps", "substeps=True"),
    call(lambda: Numerics(substeps="x"), ValueError, "substeps", "substeps='x'"),
    call(lambda: Preset(name=3), ValueError, "preset name", "Preset(name=3)"),
    call(lambda: simulate(IC, record=True), TypeError, "record must be", "record=True"),
    call(lambda: simulate(IC, orientation="x"), ValueError, "orientation", "orientation='x'"),
    call(lambda: simulate(IC, orientation=np.eye(2)), ValueError, "orientation", "orientation 2x2"),
    call(lambda: simulate(None), ValueError, "initial condition", "simulate(None)"),
    call(lambda: simulate_batch(np.zeros((2, 6, 1))), ValueError, "(m, 6)", "ics 3-D"),
    call(lambda: simulate_batch([IC], threads=0), ValueError, "threads", "simulate_batch(threads=0)"),
    call(lambda: simulate_batch([IC], l_convention="left"), ValueError, "L convention", "l_convention"),
    call(lambda: Grid("seed", "home", 2.5), ValueError, "resolution", "Grid(res=2.5)"),
    call(lambda: Grid("seed", "home", True), ValueError, "resolution", "Grid(res=True)"),
    call(lambda: Grid("seed", "home", (3, 0)), ValueError, "resolution", "Grid(res=(3, 0))"),
    call(lambda: Grid(42, "home", 3), TypeError, "slice must be", "Grid(slice=42)"),
    call(lambda: Grid("seed", "atlantis", 3), ValueError, "unknown window 'atlantis'", "Grid(window=atlantis)"),
    call(lambda: Sample("seed", "home", True), ValueError, "sample size n", "Sample(n=True)"),
    call(lambda: Sample("seed", "home", 0), ValueError, "sample size n", "Sample(n=0)"),
    call(lambda: Sample("seed", "home", 5, seed=-1), ValueError, "sample seed", "Sample(seed=-1)"),
    call(lambda: Sample("seed", "home", 5, seed=1.5), ValueError, "sample seed", "Sample(seed=1.5)"),
    call(lambda: Sample("seed", "home", 5, "halton"), ValueError, "unknown sample method 'halton'", "Sample(halton)"),
    call(lambda: Sample("seed", "home", 2**31, "sobol"), ValueError, "2**30", "Sobol beyond 2**30"),
    call(lambda: Points("seed", [["a", "b"]]), ValueError, "points", "Points(strings)"),
    call(lambda: ScanDefinition(G, make_config(), 0), ValueError, "chunk", "chunk=0"),
    call(lambda: ScanDefinition(G, make_config(), True), ValueError, "chunk", "chunk=True"),
    call(lambda: ScanDefinition(G, make_config(), float("inf")), ValueError, "chunk", "chunk=inf"),
    call(lambda: ScanDefinition(G, make_config(), 10**9), ValueError, "chunk must be at most", "chunk=1e9"),
    call(lambda: ScanDefinition(G, "seed"), TypeError, "config must be", "ScanDefinition(config=str)"),
    call(lambda: ScanDefinition(Grid("seed", "home", 10**10), make_config()), ValueError, "int64", "10**20 ICs"),
    call(lambda: scan(G, 5), TypeError, "out must be a folder path", "scan(out=5)"),
    call(lambda: scan(G, max_chunks=-1), ValueError, "max_chunks must be an integer >= 0", "max_chunks=-1"),
    call(lambda: scan(G, max_chunks=1.5), ValueError, "max_chunks", "max_chunks=1.5"),
    call(lambda: scan(G, wait=-1), ValueError, "wait", "wait=-1"),
    call(lambda: scan(G, progress="yes"), TypeError, "progress", "progress='yes'"),
    call(lambda: scan(G, dask=5), TypeError, "dask must be", "dask=5"),
    call(lambda: scan(G, dask="tcp://x y"), ValueError, "scheduler address", "dask='tcp://x y'"),
    call(lambda: scan(G, n_workers=0), ValueError, "n_workers", "n_workers=0"),
    call(lambda: list(iter_scan(G, threads=-1)), ValueError, "threads", "iter_scan(threads=-1)"),
    call(lambda: estimate_scan(G), TypeError, "defn must be a ScanDefinition", "estimate_scan(Grid)"),
    call(lambda: scan(Points("seed", [(1e308, 1e308)])), ValueError, "non-finite ICs", "overflowing points"),
    call(lambda: read_scan(42), TypeError, "folder", "read_scan(42)"),
    call(lambda: simulate(IC, record=Record(states="no")), TypeError, "Record(states=...)", "Record(states='no')"),
    call(lambda: simulate_batch([["a"] * 6]), ValueError, "initial conditions ics must be real numbers", "ics of strings"),
]


@pytest.mark.parametrize("fn, exc, words", CALLS)
def test_bad_arguments_raise_the_named_error(fn, exc, words):
    with pytest.raises(exc) as info:
        fn()
    msg = str(info.value)
    assert words in msg, msg
    assert "np.float64" not in msg and "np.int64" not in msg
    assert "\n" not in msg


def test_output_errors_are_value_errors_and_os_errors(tmp_path):
    """A bad output is a ValueError (a bad argument) and an OSError (what it is): either except catches it."""
    with pytest.raises(ValueError):
        scan(G, "/proc/x")
    with pytest.raises(OSError):
        scan(G, "/proc/x")
    (tmp_path / "afile").write_text("x")
    with pytest.raises(OutputError, match=r"'.*afile' exists and is not a folder"):
        scan(G, tmp_path / "afile")
    from dicetrace.sinks.rerun import write_rrd

    roll = simulate(seed_slice(1.65, 3.9), t_max_s=0.2, record=Record())
    with pytest.raises(OutputError, match=r"recording '.*x\.txt' must end in \.rrd"):
        write_rrd(roll, tmp_path / "x.txt")
    with pytest.raises(OutputError, match=r"is a folder"):
        write_rrd(roll, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_an_unknown_column_is_a_value_error_not_a_corrupt_chunk(tmp_path):
    from dicetrace.scan.read import label_grid

    scan(G, tmp_path / "s")
    with pytest.raises(ValueError, match="unknown column.*'nope'") as info:
        label_grid(tmp_path / "s", column="nope")
    assert "damaged" not in str(info.value) and "cannot be read" not in str(info.value)
    with pytest.raises(ValueError, match="unknown column"):
        read_scan(tmp_path / "s", columns=["outcome", "bogus"])


def test_sizes_are_exact():
    assert Grid("seed", "home", 10**10).size == 10**20
    assert Grid("seed", "home", (10**9, 3)).size == 3 * 10**9
    assert isinstance(Grid("seed", "home", np.int64(7)).size, int)


def test_warning_for_tol_on_a_fixed_step_integrator():
    """``tol`` with a fixed-step integrator has no effect: the API warns (the CLI refuses --tol there)."""
    with pytest.warns(UserWarning, match=re.escape("has no effect on rk4")):
        make_config(integrator="rk4", tol=1e-5)


def test_numpy_reals_are_stored_as_python_numbers():
    p = Preset(k=np.int64(500000), mu=np.float32(1.25))
    assert type(p.k) is int and type(p.mu) is float and p.mu == 1.25
    n = Numerics(dt_s=np.float32(0.5), tol=np.float64(1e-7))
    assert type(n.dt_s) is float and type(n.tol) is float


# -- the Python API's edges (issue 36 item 9): integer arguments, ICs that are not real numbers ----------

#: Two throws whose contact sequences outgrow a one-set buffer: 70 sets (three re-runs, 1 → 8 → 64 → 512) and 23.
ICS2 = np.asarray(seed_slice([5.79176516776336, 1.65], [3.0872428026467946, 3.9]))
INT_TYPES = [np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64, int]


def _bounded(fn, seconds: float):
    """``fn()``, failing the test when it has not returned within ``seconds`` (it keeps running in a daemon thread)."""
    import threading

    out: dict = {}

    def target():
        try:
            out["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed to the test
            out["error"] = e

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"did not return within {seconds} s"
    if "error" in out:
        raise out["error"]
    return out["value"]


def _same_batch(a, b) -> None:
    for name in ("outcome", "status_code", "steps", "set_offsets", "sets", "set_steps"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("itype", INT_TYPES, ids=lambda t: t.__name__)
def test_integer_arguments_of_every_width_are_python_ints(itype):
    """``cap=np.int8(1)`` never returned: the buffer grew 1, 8, 64, then wrapped to 0 in int8 arithmetic."""
    ref = simulate_batch(ICS2, cap=1, threads=1)
    assert ref.set_offsets[1] > CAP_GROWTH**2  # the first throw needs a 512-set buffer: past int8's range
    got = _bounded(lambda: simulate_batch(ICS2, cap=itype(1), threads=itype(1)), 120)
    _same_batch(got, ref)

BAD_COUNTS = [0, -1, np.int8(-1), np.int64(0), np.uint8(0), True, np.bool_(True), 1.0, np.float64(2.0), float("nan"),
              "8", 1 + 0j, np.array(4), [4]]


@pytest.mark.parametrize("bad", BAD_COUNTS, ids=repr)
@pytest.mark.parametrize("name", ["cap", "threads"])
def test_bad_integer_arguments_are_refused_naming_them(name, bad):
    with pytest.raises(ValueError, match=rf"^{name} must be an integer >= 1") as info:
        simulate_batch(ICS2, **{name: bad})
    assert "np." not in str(info.value)


@pytest.mark.parametrize("huge", [2**31, np.uint64(2**64 - 1), np.int64(2**62), 10**30], ids=repr)
def test_a_huge_cap_is_refused_before_anything_runs(huge):
    with pytest.raises(ValueError, match=r"^cap must be at most 2,147,483,647, got [\d,]+$"):
        simulate_batch(ICS2, cap=huge)


def test_more_threads_than_numba_has_run_as_many_as_it_has():
    import numba

    for threads in (numba.config.NUMBA_NUM_THREADS + 1, np.uint64(2**64 - 1), 10**30):
        _same_batch(simulate_batch(ICS2, threads=threads, t_max_s=0.3), simulate_batch(ICS2, threads=1, t_max_s=0.3))


IC6 = np.asarray(seed_slice(1.65, 3.9))
NOT_REAL = [
    pytest.param(IC6 + 1j, "complex numbers", id="complex array"),
    pytest.param(IC6.astype(np.complex64), "complex numbers", id="complex64, zero imaginary part"),
    pytest.param([complex(v) for v in IC6], "complex numbers", id="list of complex"),
    pytest.param(IC6.astype(object) + 1j, "got complex", id="object array of complex"),
    pytest.param(np.array([*IC6[:5], None], dtype=object), "got NoneType", id="object array with None"),
    pytest.param([*IC6[:5], "1.5"], "text", id="a string among numbers"),
    pytest.param(IC6.astype(str), "text", id="str array"),
    pytest.param(IC6.astype(bytes), "bytes", id="bytes array"),
    pytest.param(IC6 > 0, "booleans", id="bool array"),
    pytest.param(np.arange(6).astype("datetime64[s]"), "dates", id="datetime64"),
    pytest.param([*IC6[:5], 10**400], "beyond float64's range", id="an integer beyond float64"),
    pytest.param([*IC6[:5], float("nan")], "not finite", id="NaN"),
    pytest.param([*IC6[:5], -np.inf], "not finite", id="-inf"),
]


@pytest.mark.parametrize("ic, words", NOT_REAL)
def test_ics_that_are_not_real_numbers_are_refused_by_simulate_and_simulate_batch_alike(ic, words):
    """A complex array was truncated to its real part by simulate_batch (numpy's warning only)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning on the way either
        with pytest.raises(ValueError, match="initial condition") as one:
            simulate(ic)
        with pytest.raises(ValueError, match="initial condition") as many:
            simulate_batch([ic] if isinstance(ic, list) else np.reshape(ic, (1, 6)))
        if words != "booleans":  # (a list mixing a row of bools with one of floats is numbers to numpy: [1.0, 0.0])
            with pytest.raises(ValueError, match="initial condition"):
                simulate_batch([ic, IC6])
    for info in (one, many):
        assert words in str(info.value) and "\n" not in str(info.value)
    assert "ic " in str(one.value) or "ic:" in str(one.value) or "not finite" in str(one.value)


def test_real_numbers_of_any_numeric_dtype_are_accepted():
    from fractions import Fraction

    ref = simulate_batch(ICS2, t_max_s=0.3)
    as_int = np.round(ICS2 * 4) / 4  # values that every dtype below holds exactly
    ref_int = simulate_batch(as_int, t_max_s=0.3)
    for ok in (as_int.astype(np.float32), as_int.astype(object), [[Fraction(v) for v in row] for row in as_int]):
        _same_batch(simulate_batch(ok, t_max_s=0.3), ref_int)
    _same_batch(simulate_batch(ICS2.astype(object), t_max_s=0.3), ref)
    assert simulate(np.array([0, 0, -400, 300, -50, 20]), t_max_s=0.3).steps > 0  # integers


@pytest.mark.parametrize("bad", [np.eye(3) * (1 + 0j), np.eye(3).astype(bool), np.eye(3).astype(str), [[1, 0], [0, 1, 0]]],
                         ids=["complex", "bool", "str", "ragged"])
def test_an_orientation_that_is_not_real_numbers_is_refused(bad):
    with pytest.raises(ValueError, match="^orientation must be a 3×3 rotation matrix"):
        simulate(IC6, orientation=bad)


@pytest.mark.parametrize("field", ["t_max_s", "dt_s", "k", "gamma", "tol"])
def test_an_integer_beyond_float64_is_a_value_error_naming_the_option(field):
    """``t_max_s=10**400`` raised OverflowError from math.isfinite."""
    with pytest.raises(ValueError) as info:
        make_config(**{field: 10**400})
    assert {"t_max_s": "t_max", "dt_s": "dt", "tol": "tol"}.get(field, field) in str(info.value)
