"""The scheme table (``core.schemes``), the sub-step methods (``core.methods``) and how kernels are built (``core.kernels``)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

from dicetrace.core import kernels
from dicetrace.core.methods import SubstepMethod, dop853, rk4, tsit5
from dicetrace.core.schemes import SCHEMES, EventsScheme, Scheme, SummaryScheme, has_events
from dicetrace.integrators import INTEGRATORS

CORE = Path(kernels.__file__).resolve().parent


def test_every_integrator_names_a_scheme_of_the_table():
    assert {spec.scheme for spec in INTEGRATORS.values()} == set(SCHEMES)


def test_scheme_modules_provide_what_the_run_loop_reads():
    for name, mod in SCHEMES.items():
        assert isinstance(mod, Scheme), name
        assert isinstance(mod.EXACT_FLIGHT, bool), name
    contact = {n for n, m in SCHEMES.items() if n.startswith("contact_")}
    assert {n for n, m in SCHEMES.items() if isinstance(m, EventsScheme)} == contact
    assert all(m.EXACT_FLIGHT for n, m in SCHEMES.items() if n in contact)
    assert {n for n, m in SCHEMES.items() if isinstance(m, SummaryScheme)} == {"semi_implicit_euler"}


def test_sub_step_methods_provide_what_the_driver_reads():
    for m in (rk4, tsit5, dop853):
        assert isinstance(m, SubstepMethod), m.__name__
        assert 0.0 < m.ERR_EXP <= 0.25 and m.FRICTION_THETA > 0.0 and m.H0 > 0.0
    assert [m.DENSE for m in (rk4, tsit5, dop853)] == [False, True, False]


def test_no_scheme_registers_itself_and_none_is_imported_by_a_string():
    """Scheme modules hold physics only: no run loop or batch kernel bound at import, no module passing itself
    (``sys.modules[__name__]``), and nothing in core imports a module by a computed name."""
    for name, mod in SCHEMES.items():
        for attr in ("roll_trace", "roll_summary", "batch", "roll_events", "batch_events"):
            assert not hasattr(mod, attr), (name, attr)
    for path in CORE.rglob("*.py"):
        text = path.read_text()
        assert "sys.modules[__name__]" not in text, path
        assert not re.search(r"import_module\(|__import__\(", text), path


def test_kernels_are_built_once_per_scheme_in_a_named_module():
    """``kernels_of`` builds a scheme's kernels once per process, in a module numba's cache can key on by name."""
    for name, mod in SCHEMES.items():
        k = kernels.kernels_of(mod)
        assert kernels.kernels_of(mod) is k
        assert k.scheme is mod
        assert sys.modules[f"dicetrace.core.kernels.{name}"] is k
        assert (k.roll_events is None) == (not has_events(mod)) == (k.batch_events is None)
        assert k.roll_trace.py_func.__name__ == f"roll_{name}_trace"
    for spec in INTEGRATORS.values():
        assert kernels.kernels_for(spec.kernel_id).scheme is SCHEMES[spec.scheme]
