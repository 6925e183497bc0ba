"""dicetrace.simulate: one throw (simulate), many (simulate_batch), what they return, and Status."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import dicetrace
from dicetrace.ics import seed_slice
from dicetrace.params import make_config
from dicetrace.simulate import CAP_GROWTH, BatchResult, Record, simulate, simulate_batch
from dicetrace.status import LABELS, Status

SEQ_1_65_3_9 = "0-6-68-8-0-3-0-1-0-8-48-4-24-2-0-2-4-0-6-0-48-0-6"


def _ics(n: int, seed: int = 1) -> np.ndarray:
    xy = np.random.default_rng(seed).uniform(0.0, 20.0, size=(n, 2))
    return np.concatenate([seed_slice(xy[:, 0], xy[:, 1]), seed_slice([1.65], [3.9]), np.zeros((1, 6))])


def assert_batch_equals_rows(batch: BatchResult, ics: np.ndarray, **options) -> None:
    """Every row of ``batch`` equals ``simulate`` of that IC: status, outcome, steps, time, contact sets and steps."""
    assert len(batch) == len(ics) and len(batch.set_offsets) == len(ics) + 1
    for i, ic in enumerate(ics):
        r = simulate(ic, **options)
        got = (Status(int(batch.status_code[i])), int(batch.outcome[i]), int(batch.steps[i]), float(batch.t_settle_s[i]))
        assert got == (r.status, r.outcome, r.steps, r.t_settle_s), f"IC {i}"
        a, b = batch.set_offsets[i], batch.set_offsets[i + 1]
        np.testing.assert_array_equal(batch.sets[a:b], r.contact_sets, err_msg=f"IC {i}: contact sets")
        np.testing.assert_array_equal(batch.set_steps[a:b], r.contact_steps, err_msg=f"IC {i}: contact steps")
        assert batch.contact_sequences()[i] == r.contact_sequence
        assert np.array_equal(batch.ics[i].view(np.uint64), np.asarray(r.ic, dtype=np.float64).view(np.uint64))


# -- simulate_batch is simulate, row by row ----------------------------------------------------------


@pytest.mark.parametrize("cap", [1, 2, 128])
@pytest.mark.parametrize("threads", [1, 2])
def test_batch_is_bit_identical_to_single_throws_whatever_the_buffer(cap, threads):
    """cap = 1 or 2 sends every throw through the retry path (2 → 16 → 128 sets), some twice."""
    ics = _ics(40)
    batch = simulate_batch(ics, cap=cap, threads=threads)
    n_sets = np.diff(batch.set_offsets)
    if cap < 128:
        assert (n_sets > cap).all() and (n_sets > cap * CAP_GROWTH).any()  # every throw re-run, some twice
    if cap == 2:
        assert (n_sets <= cap * CAP_GROWTH).any()  # and some only once
    assert_batch_equals_rows(batch, ics)
    assert batch.contact_sequences()[40] == SEQ_1_65_3_9


@pytest.mark.parametrize(
    "options",
    [
        pytest.param(dict(preset="physical", integrator="contact-adaptive"), id="physical contact-adaptive"),
        pytest.param(dict(preset="seed", integrator="rk4", dt_s=5e-4), id="seed rk4"),
        pytest.param(dict(preset="seed", t_max_s=0.4), id="time cap"),
        pytest.param(dict(preset="seed", dt_s=0.01), id="blow-up"),
    ],
)
def test_batch_is_bit_identical_to_single_throws_for_other_kernels_and_endings(options):
    ics = _ics(20, seed=3)  # more than one work item: the batch kernel, not the one-by-one path
    batch = simulate_batch(ics, cap=2, **options)
    statuses = set(batch.status)
    if "t_max_s" in options:
        assert "time_cap" in statuses
    if options.get("dt_s") == 0.01:
        assert statuses & {"blow_up", "non_finite"}
    assert_batch_equals_rows(batch, ics, **options)


@pytest.mark.parametrize("preset", ["seed", "physical"])
def test_small_batches_run_one_by_one_with_the_batch_kernels_results(preset):
    """Up to BATCH_BLOCK ICs skip the batch kernel (one work item: one thread anyway); same bits."""
    from dicetrace.core.loop import BATCH_BLOCK

    ics = _ics(BATCH_BLOCK + 1, seed=5)
    if preset == "physical":
        ics[:, 3:] *= -1
    whole = simulate_batch(ics, preset=preset, cap=4)  # the batch kernel (and its retries, one by one)
    small = simulate_batch(ics[:BATCH_BLOCK], preset=preset, cap=4)
    for name in ("outcome", "status_code", "steps"):
        np.testing.assert_array_equal(getattr(small, name), getattr(whole, name)[:BATCH_BLOCK])
    n = small.set_offsets[-1]
    np.testing.assert_array_equal(small.set_offsets, whole.set_offsets[: BATCH_BLOCK + 1])
    np.testing.assert_array_equal(small.sets, whole.sets[:n])
    np.testing.assert_array_equal(small.set_steps, whole.set_steps[:n])
    assert set(small.status) == {"settled"}


def test_batch_l_convention_and_returned_ics():
    """ICs given in the program's L to a physical preset are the same throws as the physical L, and come back in the preset's."""
    ics = _ics(5)
    phys_l = ics * np.array([1, 1, 1, -1, -1, -1])
    a = simulate_batch(ics, preset="physical", integrator="contact-substep", l_convention="program")
    b = simulate_batch(phys_l, preset="physical", integrator="contact-substep")
    for name in ("status_code", "outcome", "steps", "set_offsets", "sets", "set_steps"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.ics, phys_l)
    np.testing.assert_array_equal(b.ics, phys_l)


def test_empty_batch():
    b = simulate_batch(np.zeros((0, 6)))
    assert len(b) == 0 and b.contact_sequences() == [] and list(b.set_offsets) == [0]
    df = b.to_pandas()
    assert len(df) == 0 and list(df.columns) == list(simulate_batch(_ics(1)).to_pandas().columns)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(config=make_config("seed"), integrator="rk4"), "pass either config or integrator, not both"),
        (dict(config=make_config("seed"), dt_s=1e-4, t_max_s=2.0), "pass either config or dt_s, t_max_s, not both"),
        (dict(config=make_config("seed"), preset="physical"), "pass either config or preset"),
        (dict(cap=0), "cap must be an integer >= 1"),
        (dict(cap=True), "cap must be an integer >= 1"),
        (dict(cap=2.0), "cap must be an integer >= 1"),
        (dict(threads=0), "threads must be an integer >= 1"),
        (dict(threads=True), "threads must be an integer >= 1"),
        (dict(l_convention="left"), "L convention must be one of program, physical"),
    ],
    ids=lambda v: v if isinstance(v, str) else None,
)
def test_batch_refuses_bad_arguments_naming_them(kwargs, words):
    with pytest.raises(ValueError, match=words):
        simulate_batch(_ics(1), **kwargs)


def test_simulate_refuses_config_with_options_and_bad_records():
    with pytest.raises(ValueError, match="pass either config or integrator, not both"):
        simulate(np.zeros(6), config=make_config("seed"), integrator="rk4")
    with pytest.raises(ValueError, match="Record\\(\\) asks for nothing"):
        Record(states=False, energy=False, forces=False)
    with pytest.raises(TypeError, match="record must be a dicetrace.Record"):
        simulate(np.zeros(6), record=True)


# -- BatchResult tables ------------------------------------------------------------------------------


def test_to_pandas_has_the_parquet_sinks_rolls_columns_and_dtypes(tmp_path):
    """BatchResult.to_pandas() is exactly what pandas reads back from the sink's rolls.parquet."""
    import pyarrow.parquet as pq

    from dicetrace.sinks.parquet import ROLLS_SCHEMA, write_tables

    batch = simulate_batch(_ics(5), preset="physical", integrator="contact-substep")
    table = batch.to_arrow()
    assert table.schema.equals(ROLLS_SCHEMA, check_metadata=False)
    assert [f.metadata for f in table.schema] == [f.metadata for f in ROLLS_SCHEMA]  # units
    df = batch.to_pandas()
    assert list(df.columns) == ROLLS_SCHEMA.names
    write_tables(tmp_path, batch)
    back = pd.read_parquet(tmp_path / "rolls.parquet")
    assert dict(df.dtypes) == dict(back.dtypes)
    pd.testing.assert_frame_equal(df, back)
    assert pq.read_table(tmp_path / "rolls.parquet").schema.metadata == table.schema.metadata
    # and the values are the batch's
    np.testing.assert_array_equal(df["outcome"], batch.outcome)
    np.testing.assert_array_equal(df["steps"], batch.steps)
    assert list(df["status"]) == list(batch.status)
    assert list(df["contact_sequence"]) == batch.contact_sequences()
    assert set(df["preset"]) == {"physical"} and set(df["integrator"]) == {"contact-substep"}
    np.testing.assert_array_equal(df[["vx", "vy", "vz", "Lx", "Ly", "Lz"]].to_numpy(), batch.ics)


def test_to_arrow_takes_ids_coordinates_and_metadata():
    import json

    xy = np.array([[1.65, 3.9], [1.5, 4.0]])
    batch = simulate_batch(seed_slice(xy[:, 0], xy[:, 1]))
    t = batch.to_arrow(ic_ids=[7, 9], coords=xy, metadata={"slice": "seed"})
    df = t.to_pandas()
    assert list(df["ic_id"]) == [7, 9] and df[["x", "y"]].to_numpy().tolist() == xy.tolist() and df["z"].isna().all()
    meta = json.loads(t.schema.metadata[b"dicetrace"])
    assert meta["slice"] == "seed" and meta["ics"] == batch.ics.tolist() and meta["dicetrace_version"] == dicetrace.__version__


# -- one throw: what a Roll and its Trace hold -----------------------------------------------------------


def test_trace_starts_at_the_ic_and_has_a_row_per_step():
    ic = seed_slice(1.65, 3.9)
    r = simulate(ic, record=Record(states=True, energy=True, forces=True))
    tr = r.trace
    assert (r.outcome, r.steps, r.status, r.contact_sequence) == (3, 540, Status.SETTLED, SEQ_1_65_3_9)
    assert r.t_settle_s == 540 * 0.001 and r.settled and r.n_contact_changes == 22
    n = r.steps + 1
    assert tr.step.tolist() == list(range(n)) and np.array_equal(tr.t_s, tr.step * 0.001)
    assert tr.cm_pos.shape == (n, 3) and tr.node_offsets.shape == (n, 8, 3) and tr.forces.shape == (n, 8, 3)
    np.testing.assert_array_equal(tr.cm_pos[0], [0.0, 0.0, 15.0])
    np.testing.assert_array_equal(tr.cm_vel[0], ic[:3])
    np.testing.assert_array_equal(tr.L[0], ic[3:])  # in the preset's convention
    np.testing.assert_array_equal(tr.node_offsets[0], make_config().initial_offsets())
    assert set(tr.energy) == {"stop_test", "kinetic_translational", "kinetic_rotational", "gravitational", "elastic", "total"}
    # node positions, rotation and quaternion describe one rigid motion
    from scipy.spatial.transform import Rotation

    np.testing.assert_allclose(Rotation.from_quat(tr.quat_xyzw).as_matrix(), tr.rotation, atol=1e-9)
    np.testing.assert_allclose(np.einsum("nij,kj->nki", tr.rotation, tr.node_offsets[0]), tr.node_offsets, atol=1e-9)
    # the contact events are the set changes
    ev = r.contact_events()
    assert list(ev.columns) == ["step", "t_s", "node", "kind"]
    assert ev.iloc[0].tolist() == [176, 0.176, 6, "enter"]
    assert (ev.groupby("step").size().index.to_numpy() == r.contact_steps[1:]).all()


def test_summary_only_and_partial_records():
    ic = seed_slice(1.65, 3.9)
    summary = simulate(ic)
    assert summary.trace is None
    energy_only = simulate(ic, record=Record(states=False, energy=True))
    tr = energy_only.trace
    assert tr.cm_pos is None and tr.node_offsets is None and tr.forces is None and tr.node_pos is None and tr.quat_xyzw is None
    assert len(tr.energy["total"]) == summary.steps + 1
    full = simulate(ic, record=Record(states=True, energy=True))
    np.testing.assert_array_equal(tr.energy["total"], full.trace.energy["total"])  # the trace path only writes
    assert (full.outcome, full.steps, full.contact_sequence) == (summary.outcome, summary.steps, summary.contact_sequence)


def test_a_failed_throw_keeps_only_finite_rows():
    r = simulate(np.array([1e300, 0, 0, 0, 0, 0]), record=Record(states=True, energy=True))
    assert r.status == Status.NON_FINITE and r.status.failed and r.outcome == -1
    assert r.steps == 1 and len(r.trace.cm_pos) == 1  # the non-finite step is dropped, the IC row kept
    assert np.isfinite(r.trace.cm_pos).all() and np.isfinite(r.trace.node_offsets).all()  # (its energy overflows)
    b = simulate(seed_slice(1.65, 3.9), dt_s=0.01, record=Record(states=True, energy=True))
    assert b.status == Status.BLOW_UP and b.status.failed and b.outcome == -1
    assert b.trace.written.all() and len(b.trace.cm_pos) == b.steps + 1


# -- Status ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("status", list(Status), ids=str)
def test_status_labels_round_trip(status):
    assert Status.from_label(status.label) is status
    assert Status.from_label(status.label.upper()) is status
    assert str(status) == status.label == f"{status}"
    assert status == status.label and status == int(status) and not (status != status.label)
    assert Status(int(status)) is status
    assert status.advice and "\n" not in status.advice
    assert status.failed == (status in (Status.NON_FINITE, Status.BLOW_UP))
    if status not in (Status.BUFFER_FULL, Status.RUNNING):  # internal: never stored
        assert LABELS[int(status)] == status.label
        assert Status.labels_of(np.array([int(status)] * 2, dtype=np.int8)).tolist() == [status.label] * 2


def test_status_from_a_label_names_the_choices():
    with pytest.raises(ValueError, match="unknown status 'resting' \\(choose from settled, time_cap, non_finite, blow_up\\)"):
        Status.from_label("resting")
    assert Status.SETTLED != "time_cap" and Status.SETTLED != 1
    assert dicetrace.Status is Status


def test_status_labels_round_trip_through_the_rolls_table():
    """A file stores the label; reading it back gives the member the batch returned."""
    ics = np.concatenate([seed_slice([1.65], [3.9]), [[1e300, 0, 0, 0, 0, 0]]])
    for options, want in ((dict(), {"settled", "non_finite"}), (dict(t_max_s=0.2), {"time_cap", "non_finite"})):
        batch = simulate_batch(ics, **options)
        df = batch.to_pandas()
        assert set(df["status"]) == want
        back = [Status.from_label(s) for s in df["status"]]
        assert back == [Status(int(c)) for c in batch.status_code]


# -- the contact schemes' sub-step budget ------------------------------------------------------------

PHYSICAL_IC = [60.0, -40.0, 150.0, 3000.0, -2000.0, 1500.0]


def test_substeps_are_zero_for_the_programs_scheme_and_counted_for_contact_schemes():
    """``Roll.substeps`` names every cause; the program's scheme has none, a contact scheme has them."""
    seed = simulate([1.65, 3.9, 0, 0, 0, 0], preset="seed")
    assert set(seed.substeps) == {"error", "cap", "friction", "end", "cut", "rejected", "redone"}
    assert not any(seed.substeps.values())
    fixed = simulate(PHYSICAL_IC, preset="physical", integrator="contact-substep")
    s = fixed.substeps
    assert fixed.settled and s["cap"] > 0 and s["cut"] > 0
    # no error control: nothing rejected, no length from the controller, and every
    # cut is a sub-step computed again, shorter, ending where the node crossed
    assert s["error"] == s["rejected"] == 0 and s["cut"] == s["redone"]
    # every change of the contact set, except a first touch after free flight (found on the exact
    # free-flight trajectory), has a node crossing the ground inside a sub-step: a cut
    sets = fixed.contact_sets
    touches = int(np.sum((sets[:-1] == 0) & (sets[1:] != 0)))
    assert 0 < touches < fixed.n_contact_changes and s["cut"] >= fixed.n_contact_changes - touches


def test_substeps_of_the_error_controlled_scheme_and_the_friction_bound():
    """DOP853's sub-steps come from its controller; the smaller v_reg, the more the friction law bounds them."""
    counts = {
        v: simulate(PHYSICAL_IC, preset="physical", integrator="contact-dop853", tol=1e-7, v_reg_cm_s=v).substeps
        for v in (10.0, 1.0)
    }
    assert counts[10.0]["error"] > 0 and counts[10.0]["redone"] >= counts[10.0]["cut"] > 0
    # the law's stiffness μ·P/(m·v_reg) grows tenfold: far more sub-steps sit on its bound
    assert counts[1.0]["friction"] > 3 * counts[10.0]["friction"] > 0
    # the summary is the same whether or not it is counted (counting never steers)
    batch = simulate_batch([PHYSICAL_IC], preset="physical", integrator="contact-dop853", tol=1e-7)
    single = simulate(PHYSICAL_IC, preset="physical", integrator="contact-dop853", tol=1e-7)
    assert (int(batch.outcome[0]), int(batch.steps[0])) == (single.outcome, single.steps)


# -- slice coordinates reach the table --------------------------------------------------------------


def test_seed_slice_coordinates_reach_the_batch_table(tmp_path):
    """The README's example: ``simulate_batch(seed_slice(xs, ys)).to_pandas()`` has x, y (z null on the 2-D slice)."""
    from dicetrace.sinks.parquet import write_tables

    xs, ys = np.meshgrid(np.linspace(1.0, 2.0, 3), np.linspace(3.5, 4.5, 2))
    ics = seed_slice(xs.ravel(), ys.ravel())
    batch = simulate_batch(ics, t_max_s=0.05)
    df = batch.to_pandas()
    assert df["x"].tolist() == xs.ravel().tolist() and df["y"].tolist() == ys.ravel().tolist() and df["z"].isna().all()
    np.testing.assert_array_equal(df[["vx", "vy", "vz", "Lx", "Ly", "Lz"]].to_numpy(), np.asarray(ics))
    # a selection of rows keeps its coordinates; explicit ones win; a plain array has none
    sub = simulate_batch(ics[[4, 1]], t_max_s=0.05).to_pandas()
    assert sub["x"].tolist() == [xs.ravel()[4], xs.ravel()[1]] and sub["y"].tolist() == [ys.ravel()[4], ys.ravel()[1]]
    assert batch.to_pandas(coords=np.zeros((6, 2)))["x"].tolist() == [0.0] * 6
    assert simulate_batch(np.asarray(ics), t_max_s=0.05).to_pandas()[["x", "y", "z"]].isna().all().all()
    # one IC, the 3-D slice, and the Parquet sink all see them
    assert simulate_batch(seed_slice(1.65, 3.9), t_max_s=0.05).to_pandas()[["x", "y"]].values.tolist() == [[1.65, 3.9]]
    three = simulate_batch(seed_slice([1.0, 2.0], [3.5, 4.0], [0.25, 0.5]), t_max_s=0.05).to_pandas()
    assert three[["x", "y", "z"]].values.tolist() == [[1.0, 3.5, 0.25], [2.0, 4.0, 0.5]]
    write_tables(tmp_path / "out", batch)
    back = pd.read_parquet(tmp_path / "out" / "rolls.parquet")
    assert back["x"].tolist() == xs.ravel().tolist()


# -- chunks: bounded memory, the same result bit for bit ----------------------------------------------------

_FIELDS = ("ics", "outcome", "status_code", "steps", "t_settle_s", "set_offsets", "sets", "set_steps", "coords")


def _bit_identical(a: BatchResult, b: BatchResult) -> None:
    for name in _FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if x is None or y is None:
            assert x is None and y is None, name
            continue
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name


@pytest.mark.parametrize("preset", ["seed", "physical"])
def test_chunked_batches_are_bit_identical_to_one_chunk(preset):
    """Chunks of 1, of a few ICs, of a kernel block (16) and across blocks, with buffers that must regrow (cap 1)."""
    rng = np.random.default_rng(8)
    xy = rng.uniform(0.0, 10.0, size=(40, 2))
    ics = seed_slice(xy[:, 0], xy[:, 1])
    if preset == "physical":
        ics = ics * np.array([1, 1, 1, -1, -1, -1])
    whole = simulate_batch(ics, preset=preset, chunk=10**9, cap=1, t_max_s=1.0)
    assert np.diff(whole.set_offsets).max() > CAP_GROWTH  # some throws outgrew two buffers
    for chunk, cap in [(1, 1), (3, 1), (16, 1), (17, 128), (39, 1), (np.int16(40), 128), (None, 1)]:
        _bit_identical(simulate_batch(ics, preset=preset, chunk=chunk, cap=cap, t_max_s=1.0), whole)


def test_a_batch_holds_its_result_and_one_chunk_not_every_buffer():
    """Peak memory (numpy's allocations, traced) of 20,000 ICs in chunks of 1,024: the result plus a chunk.

    One chunk for all held 20,000 × 128 contact-set buffers (5 bytes a set, and a 1-byte mask): over 15 MB.
    """
    import tracemalloc

    from dicetrace.batch_chunks import RESULT_BYTES_PER_IC, chunk_bytes_per_ic

    m, chunk = 20_000, 1024
    xy = np.random.default_rng(2).uniform(0.0, 5.0, size=(m, 2))
    ics = np.asarray(seed_slice(xy[:, 0], xy[:, 1]))
    simulate_batch(ics[:40], t_max_s=0.02)  # load the kernels outside the trace
    tracemalloc.start()
    try:
        res = simulate_batch(ics, t_max_s=0.02, chunk=chunk)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    bound = m * (RESULT_BYTES_PER_IC + 5 * 4) + 2 * chunk * chunk_bytes_per_ic(128)
    assert peak < bound < m * 128 * 6, (peak, bound)
    assert len(res) == m


def test_a_batch_that_cannot_fit_is_refused_before_anything_runs(monkeypatch):
    import dicetrace.batch_chunks as chunks

    ran = []
    monkeypatch.setattr(chunks, "_run_batch", lambda *a: ran.append(1))
    monkeypatch.setattr(chunks, "available_memory", lambda: 2**20)  # 1 MiB
    ics = np.asarray(seed_slice(np.linspace(1, 2, 30_000), np.linspace(3.5, 4.5, 30_000)))
    with pytest.raises(ValueError) as info:
        simulate_batch(ics)
    msg = str(info.value)
    assert msg.startswith("simulate_batch: 30,000 ICs need at least ") and "GiB of memory available" in msg, msg
    assert "0.000977 GiB of memory available" in msg and "\n" not in msg
    with pytest.raises(ValueError, match=r"chunk of 16 ICs with cap 100,000.*a smaller chunk or cap"):
        simulate_batch(ics[:100], cap=100_000, chunk=16)
    assert not ran


@pytest.mark.parametrize("bad", [0, -5, np.int8(-1), True, 2.0, float("nan"), "64"], ids=repr)
def test_a_bad_chunk_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="^chunk must be an integer >= 1 or None"):
        simulate_batch(seed_slice([1.0], [3.5]), chunk=bad)


def test_trace_rotation_of_a_tilted_start_is_the_start_orientation():
    """The trace's rotation matrices read the half side off the offsets' length, so a tilted start gives its
    own orientation at row 0 and orthonormal matrices after (the largest offset component is no half side)."""
    from scipy.spatial.transform import Rotation

    orient = Rotation.from_euler("xyz", [0.4, -0.3, 1.1]).as_matrix()
    r = simulate([50.0, 20.0, 0.0, 400.0, -300.0, 200.0], t_max_s=0.05, orientation=orient,
                 record=Record(states=True))
    rot = r.trace.rotation
    np.testing.assert_allclose(rot[0], orient, atol=1e-12)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)
