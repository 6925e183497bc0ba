"""``dicetrace throw``: hand throws of any die, the face table with Wilson intervals, the rows as Parquet."""

from __future__ import annotations

import json
import re

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from dicetrace.commands.throw import face_table
from dicetrace.simulate import simulate


def _table_counts(stdout: str) -> list[int]:
    return [int(m.group(2)) for m in re.finditer(r"^ +([1-6]) +(\d+) ", stdout, re.M)]


@pytest.mark.slow
def test_a_box_thrown_writes_every_row_with_its_pose_and_counts_them(tmp_path, dicetrace_cli):
    res = dicetrace_cli("throw", "--n", "300", "--die", "2,2,1.2", "--seed", "5", "--out", str(tmp_path / "t"),
                        "--quiet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    t = pq.read_table(tmp_path / "t" / "rolls.parquet")
    assert t.num_rows == 300 and t.column("ic_id").to_pylist() == list(range(300))
    assert {"qx", "qy", "qz", "qw", "z0_cm"} <= set(t.column_names)
    meta = json.loads(t.schema.metadata[b"dicetrace"])
    assert meta["config"]["preset"]["half_extents_cm"] == [1.0, 1.0, 0.6]
    assert meta["throw"]["model"] == "casual" and meta["throw"]["seed"] == 5 and meta["n_ics"] == 300
    outcome = t.column("outcome").to_numpy()
    assert _table_counts(res.stdout) == [int(np.sum(outcome == f)) for f in range(1, 7)]
    assert "a fair die?" not in res.stdout  # no fairness test for a box
    # a flat box lands on its large faces (3, 4) more often than a third of the time
    assert np.sum((outcome == 3) | (outcome == 4)) > 0.5 * 300
    # a row is the throw from its pose
    i = 17
    row = {c: t.column(c)[i].as_py() for c in t.column_names}
    r = simulate([row[c] for c in ("vx", "vy", "vz", "Lx", "Ly", "Lz")], preset="physical",
                 half_extents_cm=(1.0, 1.0, 0.6), z0_cm=row["z0_cm"],
                 orientation=Rotation.from_quat([row["qx"], row["qy"], row["qz"], row["qw"]]).as_matrix())
    assert (r.outcome, r.steps) == (row["outcome"], row["steps"])


@pytest.mark.slow
def test_the_same_seed_gives_the_same_throws_and_another_seed_others(tmp_path, dicetrace_cli):
    runs = {}
    for name, seed in (("a", "1"), ("b", "1"), ("c", "2")):
        res = dicetrace_cli("throw", "--n", "50", "--seed", seed, "--out", str(tmp_path / name), "-q", cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert "a fair die? chi-square test of equal shares: p = " in res.stdout
        runs[name] = pq.read_table(tmp_path / name / "rolls.parquet").drop(["contact_sets"])
    assert runs["a"].equals(runs["b"]) and not runs["a"].equals(runs["c"])


@pytest.mark.parametrize("args, message", [
    (["--n", "0"], "--n must be a whole number in [1, 100,000,000], got 0"),
    (["--throw", "wild"], "--throw must be one of casual, gentle, vigorous, got 'wild'"),
    (["--die", "2,2"], "--die needs three sides in cm"),
    (["--preset", "seed", "--die", "2,2,3"], "--integrator: preset 'seed' is no uniform cube"),
    (["--threads", "0"], "--threads must be >= 1, got 0"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, dicetrace_cli, args, message):
    res = dicetrace_cli("throw", *args, "--out", str(tmp_path / "t"), cwd=tmp_path)
    assert res.returncode == 2 and message in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert not (tmp_path / "t").exists()


def test_the_face_table_is_wilsons_interval_of_each_face_and_pearsons_test():
    outcome = np.repeat([1, 2, 3, 4, 5, 6, 0, -1], [150, 170, 160, 180, 140, 200, 3, 1])
    text, numbers = face_table(outcome, cube=True)
    assert numbers["faces"] == [150, 170, 160, 180, 140, 200] and numbers["on_face"] == 1000
    assert (numbers["edge"], numbers["unsettled"]) == (3, 1)
    for f, k in enumerate(numbers["faces"], 1):
        ci = stats.binomtest(k, 1000).proportion_ci(method="wilson")
        assert f"{f:>4}  {k:>6}  {k / 1000:9.4f}   {ci.low:.4f}-{ci.high:.4f}" in text
    assert numbers["fair_chi2_p"] == pytest.approx(stats.chisquare(numbers["faces"]).pvalue, rel=1e-12)
    assert "on a face 1000, on an edge 3, at the time cap 1" in text
