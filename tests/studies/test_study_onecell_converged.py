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
    # exact contact events: the same maps and throws, with the events' own cells
    ev = e["events"]
    assert ev["dt_s"] == 1e-3 and ev["fine_dt_s"] == 1e-5
    assert [s["min_set_s"] for s in ev["by_min_set"]] == list(t["min_set_s"])
    for s in ev["by_min_set"]:
        assert all(0.0 <= s[k] <= 1.0 for k in ("same_events_at_fine_dt", "same_as_sampled_seq_dt",
                                               "same_as_sampled_exact_dt", "fine_same_as_sampled_exact_dt"))
    # the raw events have at least the sets of every coarse-grained sequence
    assert ev["by_min_set"][0]["mean_events"] >= ev["by_min_set"][-1]["mean_events"]
    for lv in t["levels"]:
        raw = lv["events"]["by_min_set"][0]
        assert raw["n_nodes"] == lv["events"]["cell_nodes"] and 1 <= raw["n_labels"] <= raw["n_subcells"]
    for key in ("stacks", "subcells", "exact", "periods", "exact_events", "subcells_events"):
        assert R["tables"][key]
    assert "exact contact events" in R["verdict"]["topology"]
    assert "exact contact events" in R["verdict"]["topology_answer"] and "section p" in R["verdict"]["topology_answer"]


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


def _results(fractions, interior, singletons) -> dict:
    lv = [{"res": n, "fraction": f, "stderr": 0.02, "n_cells": 60, "windows": [{"n_joined": round(60 * f), "n_cells": 60}]}
          for n, f in zip((16, 24, 32), fractions)]
    per = {"dx": 0.1, "dy": 0.02, "dx_stderr": 0.001, "dy_stderr": 0.001, "strength": 0.3,
           "interior_fraction": interior}
    sub = [{"n_labels": 10, "n_subcells": 12, "frac_nodes_in_singletons": s} for s in singletons]
    exact = {"n": 10, "same_outcome_exact_dt": 1.0, "same_outcome_program_dt": 1.0,
             "same_when_sampled_at_program_dt": 0.0, "mean_sets_sampled_at_program_dt": 40.0,
             "by_min_set": [{"same_at_exact_dt": 0.9, "same_at_program_dt": 0.0, "mean_sets": 50.0}] * 3}
    return {"model": "physical, contact-tsit5 tol 2e-09 uniform", "stacks": {"levels": lv, "verdict": "converged" if fractions[-1] == fractions[-2] else "undetermined",
                       "certificate_min": 0.999, "certificate_word": "converged"},
            "periods": {"window": "zoom-out", "periods": [per], "certificate": {"certificate": 0.995, "word": "converged"},
                        "frac_nodes_in_singletons": 0.1, "texture_offcentre_max_corr": 0.4,
                        "outcome_offcentre_max_corr": 0.1},
            "topology": {"exact": exact, "dt_s": 1e-5, "levels": [{"res": n, "cell_label": 5, "cell_nodes": 100,
                                                             "by_min_set": [s] * 3}
                                                    for n, s in zip((32, 96), sub)]}}


def test_the_verdicts_follow_the_numbers():
    from dicetrace.studies.study_onecell_converged_render import verdicts

    v = verdicts(_results((0.2, 0.5, 0.5), 1.0, (0.9, 0.3)))
    # a join through grid nodes is no verified path in IC space: whatever the series does, no lower bound, and the
    # answer is undetermined
    assert "has stopped moving" in v["stacks"] and "**not a lower bound**" in v["stacks"]
    assert "**withdrawn**" in v["stacks"] and "30/60" in v["stacks"] and "(one window: 30/60)" in v["stacks"]
    assert v["answer"].startswith("**Undetermined**") and "0.500 ± 0.020 at 32³" in v["answer"]
    assert "lower bound" in v["answer"] and "Fewer cells than regions" not in v["answer"]
    assert "repeats with period vectors (0.1000 ± 0.0010, 0.0200 ± 0.0010)" in v["periods"]
    assert "the cell has sub-cells" in v["topology"]
    # the sequences reproduce on 0.9 of the checked throws, below 0.99: statistics only
    assert v["topology_answer"].startswith("**Statistics only**") and "0.90–0.90" in v["topology_answer"]
    assert "**statistics only**" in v["topology"]
    v = verdicts(_results((0.2, 0.3, 0.5), 0.3, (0.95, 0.9)))
    assert "still moves" in v["stacks"] and v["answer"].startswith("**Undetermined**")
    assert "no period vector that survives the bootstrap" in v["periods"]
    assert "**not** topologically the same" not in v["topology"]  # not certified: no verdict on the die
    # sequences that reproduce on 0.995: the verdicts on the die stand
    r = _results((0.2, 0.5, 0.5), 1.0, (0.9, 0.3))
    r["topology"]["exact"]["by_min_set"] = [{**r["topology"]["exact"]["by_min_set"][0], "same_at_exact_dt": 0.995}] * 3
    assert verdicts(r)["topology_answer"].startswith("**Sub-cells emerge**")
    r = _results((0.2, 0.3, 0.5), 0.3, (0.95, 0.9))
    r["topology"]["exact"]["by_min_set"] = [{**r["topology"]["exact"]["by_min_set"][0], "same_at_exact_dt": 0.995}] * 3
    v = verdicts(r)
    assert "**not** topologically the same" in v["topology"]
    assert v["topology_answer"].startswith("**No**") and "exact contact events" not in v["topology_answer"]
    # three windows: the spread between them beside the binomial error
    r = _results((0.2, 0.5, 0.5), 1.0, (0.9, 0.3))
    r["stacks"]["levels"][-1]["windows"] = [{"n_joined": 2, "n_cells": 9}, {"n_joined": 15, "n_cells": 28},
                                            {"n_joined": 18, "n_cells": 24}]
    assert "± 0.153 (between the windows: 2/9, 15/28, 18/24, from 0.22 to 0.75)" in verdicts(r)["stacks"]


def test_rerender_changes_no_number(quick_run, tmp_path):
    import json
    import shutil

    from dicetrace.studies.study_onecell_converged import rerender

    out, results = quick_run
    (tmp_path / "results").mkdir()
    shutil.copy2(out / "results" / "onecell_converged.json", tmp_path / "results")
    R = json.loads(rerender(tmp_path).read_text())
    before = results["onecell_converged"]
    assert R["tables"] == before["tables"] and R["verdict"] == before["verdict"]
    assert R["stacks"] == before["stacks"] and (tmp_path / R["figures"]["p_join"]["path"]).is_file()
