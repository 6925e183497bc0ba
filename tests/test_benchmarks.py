"""The benchmark scripts that edit the kernels' source still find what they edit.

``benchmarks/bench_cost_split.py`` measures each part of ``contact-tsit5`` by a
variant of the driver with that part done twice, and
``benchmarks/bench_step_limits.py`` counts what limits its sub-steps with
lines added to the driver; both edit the driver's source.  When the driver
changes, an edited line can vanish and the script stops with a message:
building the variants (no compiling) is enough to catch that here.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str):
    """The benchmark script ``name`` as a module (benchmarks/ on the path, as when it runs)."""
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cost_split_variants_build():
    table = _load("bench_cost_split").variants()
    assert list(table)[0] == "plain"
    assert {"substep", "stages", "error", "end forces", "cut test", "interpolation", "step-end forces",
            "flight piece", "impact search"} <= set(table)
    for name, (factory, over) in table.items():
        assert callable(factory), name
        if name in ("cut test", "interpolation", "step-end forces", "end forces", "flight piece", "impact search"):
            # an edited copy of the driver's factory, not the factory itself
            assert factory.__name__.startswith("make_drive_"), name
            assert not over, name
        else:
            assert factory.__name__ == "make_drive", name
    # the method's functions swapped in are the ones the driver reads
    assert set(table["substep"][1]) == set(table["stages"][1]) == {"substep"}
    assert set(table["error"][1]) == {"error"}


def test_step_limits_counters_build():
    mod = _load("bench_step_limits")
    factory = mod.instrumented_drive()
    assert factory.__name__ == "make_drive_limits"
    # every counter the script writes lies inside the field it adds to the state record
    rows, cols = mod.COUNTED.fields["limits"][0].shape
    assert max(mod.ROW_LAM + 2, mod.ROW_OMEGA + 2, mod.ROW_REJECTED, mod.ROW_ACCEPTED) < rows
    assert len(mod.CONTEXTS) <= cols and len(mod.LAM_EDGES) + 1 <= cols and len(mod.OMEGA_EDGES) + 1 <= cols
    # which holds every field of the state record, with its values from new_states
    S = mod.counted_states()
    base = mod.new_states(1)
    for name in mod.STATE.names:  # same type and offset: numba takes COUNTED as a subtype of STATE
        assert S.dtype.fields[name][:2] == base.dtype.fields[name][:2], name
        assert np.array_equal(S[0][name], base[0][name]), name
    assert not S[0]["limits"].any()
    assert mod._ranges((0.1, 0.3)) == ["≤ 0.1", "0.1–0.3", "> 0.3"]
