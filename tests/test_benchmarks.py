"""The benchmark scripts that edit the kernels' source still find what they edit.

``benchmarks/bench_cost_split.py`` measures each part of ``contact-tsit5`` by a
variant of the driver with that part done twice, made by replacing lines of
the driver's source.  When the driver changes, a replaced line can vanish and
the script stops with a message: building the variants (no compiling) is
enough to catch that here.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_cost_split.py"


def _load():
    spec = importlib.util.spec_from_file_location("bench_cost_split", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cost_split_variants_build():
    table = _load().variants()
    assert list(table)[0] == "plain"
    assert {"substep", "stages", "error", "end forces", "cut test", "interpolation", "step-end forces",
            "flight piece", "impact search"} <= set(table)
    for name, (template, over) in table.items():
        assert callable(template), name
        if name in ("cut test", "interpolation", "step-end forces", "end forces", "flight piece", "impact search"):
            # an edited copy of the driver, not the driver itself
            assert template.__name__ != "drive", name
