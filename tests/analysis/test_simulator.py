"""``dicetrace.analysis.simulator``: classifiers of slice points, by simulation, for the analysis measures."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from dicetrace.analysis import bisect_boundary, canonical_contact_sequence
from dicetrace.analysis.simulator import (
    classify_on_slice,
    resolve_window,
    run_on_slice,
    sample_window,
    settle_on_slice,
    window_points,
)
from dicetrace.ics import seed_slice
from dicetrace.simulate import simulate


@pytest.fixture(scope="module")
def writeup_points(reference_dir):
    with open(reference_dir / "writeup_points.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    xy = np.array([[float(r["x"]), float(r["y"])] for r in rows])
    return xy, rows


def test_classify_at_the_six_writeup_points(writeup_points):
    xy, rows = writeup_points
    labels = classify_on_slice("seed")(xy)
    assert labels.dtype == np.int64
    assert labels.tolist() == [int(r["outcome"]) for r in rows]


def test_settle_times_are_the_programs_steps(writeup_points):
    xy, rows = writeup_points
    labels, t = settle_on_slice("seed")(xy)
    assert labels.tolist() == [int(r["outcome"]) for r in rows]
    np.testing.assert_allclose(t, [int(r["steps"]) * 0.001 for r in rows], rtol=0, atol=1e-12)


def test_contact_sequence_labels(writeup_points):
    xy, rows = writeup_points
    seqs = classify_on_slice("seed", label="contact_sequence")(xy)
    assert seqs.dtype == object
    assert seqs.tolist() == [r["contact_sequence"] for r in rows]
    rot = classify_on_slice("seed", label="contact_sequence_rotations")(xy)
    assert rot.tolist() == [canonical_contact_sequence(r["contact_sequence"], canonical="rotations") for r in rows]


def test_point_shapes_and_counters():
    c = classify_on_slice("seed")
    assert c.ndim == 2
    assert c([1.65, 3.9]).tolist() == [3]  # one point (d,) -> (1,)
    assert c(np.zeros((0, 2))).shape == (0,)
    with pytest.raises(ValueError, match="2 columns"):
        c([[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match="non-finite"):
        c([[np.nan, 1.0]])
    assert c.n_evals == 1 and c.n_calls == 2
    with pytest.raises(ValueError, match="label must be"):
        classify_on_slice("seed", label="face")


def test_slice_specs_agree():
    pts = np.array([[1.65, 3.9], [0.05, 0.07], [7.5, 2.25]])
    named = classify_on_slice("seed")(pts)
    func = classify_on_slice(lambda p: seed_slice(p[:, 0], p[:, 1]))(pts)
    from dicetrace.ics import get_slice

    obj = classify_on_slice(get_slice("seed"))(pts)
    three = classify_on_slice("seed3")(np.column_stack([pts, np.zeros(len(pts))]))
    direct = [simulate(seed_slice(x, y)).outcome for x, y in pts]
    assert named.tolist() == func.tolist() == obj.tolist() == three.tolist() == direct


def test_overrides_and_presets():
    c = classify_on_slice("seed", gamma=0.01)
    assert c.config.preset.gamma == 0.01
    p = np.array([[0.05, 0.05]])
    _, t5 = settle_on_slice("seed")(p)
    _, t10 = settle_on_slice("seed", gamma=0.01)(p)
    assert simulate(seed_slice(0.05, 0.05), config=c.config).t_settle_s == pytest.approx(t10[0])
    assert t5[0] != t10[0]
    # the seed slice's L is the program's: the physical preset gets it negated (its own convention)
    ic = seed_slice(0.05, 0.05)
    phys = ic.copy()
    phys[3:] = -phys[3:]
    assert classify_on_slice("seed", preset="physical")(p)[0] == simulate(phys, preset="physical").outcome


def test_sample_window_is_the_programs_grid():
    s = sample_window("home", 5)
    assert s.labels.shape == (5, 5) and s.t_settle_s.shape == (5, 5)
    np.testing.assert_array_equal(s.axes[0], 0.0 + np.arange(5) / 4.0 * 0.1)
    assert s.extent == [(0.0, 0.1), (0.0, 0.1)]
    assert s.spacing == pytest.approx((0.025, 0.025))
    for i, j in ((0, 0), (1, 3), (4, 2)):
        assert s.labels[i, j] == simulate(seed_slice(s.axes[0][i], s.axes[1][j])).outcome
    pts, shape, axes = window_points(((1.0, 2.0), (3.5, 4.5), (0.0, 1.0)), (3, 2, 2))
    assert shape == (3, 2, 2) and pts.shape == (12, 3)
    np.testing.assert_array_equal(pts[1], [1.0, 3.5, 1.0])  # x slowest, z fastest
    assert resolve_window("red-sea") == ((1.0, 2.0), (3.5, 4.5))


def test_run_on_slice_summaries():
    r = run_on_slice([[1.65, 3.9], [1.5, 4.0]], "seed", sequences=True)
    assert r.outcome.tolist() == [3, 3]
    assert r.steps.tolist() == [540, 552]
    assert r.settled.all()
    assert r.sequences[0] == "0-6-68-8-0-3-0-1-0-8-48-4-24-2-0-2-4-0-6-0-48-0-6"


def test_unsettled_throws_are_label_minus_one():
    from dicetrace.params import make_config

    c = classify_on_slice("seed", config=make_config("seed", t_max_s=0.2))
    labels, t = settle_on_slice("seed", config=c.config)([[1.65, 3.9]])
    assert labels.tolist() == [-1]
    assert t[0] == pytest.approx(0.2)


def test_chunked_batches_match_one_batch():
    rng = np.random.default_rng(3)
    pts = rng.random((37, 2)) * 0.1
    one = classify_on_slice("seed")(pts)
    chunked = classify_on_slice("seed", chunk=8)(pts)
    assert one.tolist() == chunked.tolist()


def test_feeds_the_analysis_callables():
    c = classify_on_slice("seed")
    a, b = np.array([1.65, 3.9]), np.array([0.0198, 0.01827])  # outcomes 3 and 5
    br = bisect_boundary(c, a, b, tol=1e-6)
    assert br.label_lo == 3 and br.label_hi != 3
    assert br.width < 1e-6
    assert c.n_evals == br.n_evals


def test_a_config_with_options_is_refused_as_by_every_entry_point():
    """The analysis callables take a config or the options, never both: params.resolve_config's one rule."""
    from dicetrace.params import ConfigError, make_config, resolve_config

    cfg = make_config("seed", t_max_s=0.2)
    with pytest.raises(ConfigError, match="pass either config or gamma, not both") as exc:
        classify_on_slice("seed", config=cfg, gamma=0.01)
    assert exc.value.fields == ("gamma",)
    with pytest.raises(ConfigError, match="pass either config or gamma"):
        resolve_config(cfg, gamma=0.01)
    assert classify_on_slice("seed", config=cfg).config is cfg
    assert classify_on_slice("seed", preset="physical", gamma=0.01).config == make_config("physical", gamma=0.01)


def test_window_and_settle_take_run_and_classify_options():
    # sample_window passes its options to run_on_slice, settle_on_slice to classify_on_slice
    s = sample_window("home", 2, sequences=True, chunk=3, gamma=0.01)
    r = run_on_slice(window_points(resolve_window("home"), 2)[0], "seed", sequences=True, gamma=0.01)
    assert s.sequences.shape == (2, 2) and s.sequences.ravel().tolist() == r.sequences
    assert s.labels.ravel().tolist() == r.outcome.tolist()
    assert sample_window("home", 2).sequences is None
    settle = settle_on_slice("seed", label="contact_sequence", chunk=1, gamma=0.01)
    assert (settle.label, settle.chunk, settle.config.preset.gamma) == ("contact_sequence", 1, 0.01)
    labels, t = settle([[1.65, 3.9]])
    assert labels[0] == classify_on_slice("seed", label="contact_sequence", gamma=0.01)([[1.65, 3.9]])[0]
    with pytest.raises(ValueError, match="label must be"):
        settle_on_slice("seed", label="face")
