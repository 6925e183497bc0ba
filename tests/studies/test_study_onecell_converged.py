"""Study p (onecell_converged): registered, and its quick run's results (part of the shared ``dicetrace analyze all
--quick``, tests/studies/conftest.py).

The full run is ``dicetrace analyze onecell-converged --out analysis``.
"""

from __future__ import annotations

import numpy as np

from dicetrace.studies import LETTERS, TITLES, resolve
from dicetrace.studies.study_onecell_converged import QUICK_LEVELS, _sampled
from dicetrace.studies.text import CONVERGED_MIN


def test_registered_as_study_p():
    assert LETTERS["p"] == "onecell_converged" and resolve(["p"]) == ["onecell_converged"]
    assert resolve(["onecell-converged"]) == ["onecell_converged"] and "onecell_converged" in TITLES


def test_quick_run_results(quick_run):
    out, results = quick_run
    R = results["onecell_converged"]
    assert R["quick"] is True and "uniform" in R["model"] and "contact-dop853" in R["independent"]
    for key in ("p_join", "p_stack_slices", "p_periods", "p_subcells"):
        assert (out / R["figures"][key]["path"]).is_file()
    st = R["stacks"]
    assert [r["res"] for r in st["levels"]] == list(QUICK_LEVELS)
    for r in st["levels"]:
        assert r["n_cells"] == sum(w["n_cells"] for w in r["windows"])
        assert r["n_joined"] == sum(w["n_joined"] for w in r["windows"]) <= r["n_cells"]
        if r["n_cells"]:
            assert r["fraction"] == r["n_joined"] / r["n_cells"]
        c = r["certificate"]
        assert c["certificate"] == min(c["tightened"]["fraction"], c["independent"]["fraction"])
        assert c["word"] == ("converged" if c["certificate"] >= CONVERGED_MIN else "statistics only")
    assert st["verdict"] in ("converged", "undetermined")
    assert st["certificate_word"] in ("converged", "statistics only")
    t = R["topology"]
    for lv in t["levels"]:
        raw = lv["by_min_set"][0]
        assert raw["min_set_s"] == 0.0 and raw["n_nodes"] == lv["cell_nodes"]
        assert 1 <= raw["n_labels"] <= raw["n_subcells"] <= raw["n_nodes"]
    e = t["exact"]
    assert e["dt_s"] == 1e-5 and e["exact_dt_s"] == 1e-6 and e["program_dt_s"] == 1e-3
    assert all(0.0 <= s["same_at_exact_dt"] <= 1.0 for s in e["by_min_set"])
    for key in ("stacks", "subcells", "exact", "periods"):
        assert R["tables"][key]


class _Batch:
    """Two throws' contact sets as a batch summary holds them (sets first seen at steps, the last step)."""

    def __init__(self):
        self.sets = np.array([0, 1, 3, 1, 0, 4, 0], dtype=np.uint8)
        self.set_steps = np.array([0, 5, 7, 30, 0, 12, 13], dtype=np.int32)
        self.set_offsets = np.array([0, 4, 7])
        self.steps = np.array([45, 25])

    def __len__(self):
        return 2


def test_sampling_a_throw_at_a_longer_step_misses_the_short_sets():
    # throw 1: {1} at 5–6, {1,2} at 7–29, {1} from 30 on; sampled every 10 steps (10, 20, 30, 40) it reads
    # {1,2}, {1,2}, {1}, {1}: the first {1} (2 steps) is missed.  Throw 2: {3} lasts one step (12): not seen at all.
    s = _sampled(_Batch(), 10)
    assert s.tolist() == ["0-12-1", "0"]
    assert _sampled(_Batch(), 1).tolist() == ["0-1-12-1", "0-3-0"]  # at its own step: the whole sequence
