"""dicetrace.tables: the per-node contact events every table, the Rerun log and ``Roll.contact_events`` read."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from dicetrace.params import make_config
from dicetrace.simulate import text_to_sets
from dicetrace.tables import node_events


def _batch(sequences, steps, times=None):
    """A BatchResult-shaped stand-in holding only given contact sequences (program text form)."""
    sets = [text_to_sets(t) for t in sequences]
    m = len(sets)
    return SimpleNamespace(
        config=make_config("seed"), ics=np.zeros((m, 6)), outcome=np.ones(m), status_code=np.zeros(m),
        steps=np.full(m, 100), t_settle_s=np.full(m, 0.1), coords=None,
        set_offsets=np.concatenate([[0], np.cumsum([len(s) for s in sets])]),
        sets=np.concatenate(sets), set_steps=np.concatenate([np.asarray(s) for s in steps]),
        set_times=None if times is None else np.concatenate([np.asarray(t, float) for t in times]),
    )


def test_node_events_enter_and_leave_by_row_step_and_node():
    # the second throw starts from the empty set again, not from the first throw's last set (8)
    batch = _batch(["0-6-68-8", "0-1357-0"], [[0, 10, 12, 15], [0, 30, 31]])
    row, step, t_s, node, entered = node_events(batch)
    got = list(zip(row.tolist(), step.tolist(), node.tolist(), entered.tolist()))
    assert got == [
        (0, 10, 6, True), (0, 12, 8, True), (0, 15, 6, False),
        (1, 30, 1, True), (1, 30, 3, True), (1, 30, 5, True), (1, 30, 7, True),
        (1, 31, 1, False), (1, 31, 3, False), (1, 31, 5, False), (1, 31, 7, False),
    ]
    np.testing.assert_array_equal(t_s, step * 1e-3)  # the seed preset's dt: each event at the end of its step


def test_node_events_take_the_exact_times_where_the_throws_have_them():
    times = [[0.0, 0.0093, 0.0111, 0.0142]]
    row, step, t_s, node, entered = node_events(_batch(["0-6-68-8"], [[0, 10, 12, 15]], times))
    np.testing.assert_array_equal(t_s, [0.0093, 0.0111, 0.0142])
    np.testing.assert_array_equal(step, [10, 12, 15])


def test_trajectory_files_hold_no_negative_zero(tmp_path):
    """Zeros are written as 0.0, never -0.0: a drop with no spin on the physical preset (its L, the program's
    negated, is -0.0 once the die lands) read back from trajectory.parquet."""
    import pyarrow.parquet as pq

    from dicetrace.simulate import Record, simulate
    from dicetrace.sinks.parquet import write_tables

    roll = simulate([0.0, 0.0, -100.0, 0.0, 0.0, 0.0], preset="physical", t_max_s=0.2,
                    record=Record(states=True, energy=True))
    assert np.signbit(roll.trace.L).any()  # what the table must not pass on
    write_tables(tmp_path, roll)
    table = pq.read_table(tmp_path / "trajectory.parquet")
    t = table.column("t_s").to_numpy()
    assert t[0] == 0.0 and not np.signbit(t[0])
    for name in table.column_names:
        col = table.column(name).to_numpy()
        if col.dtype.kind == "f":
            assert not ((col == 0) & np.signbit(col)).any(), name
