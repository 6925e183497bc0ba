"""What a simulation keeps is one request, ``Record``: the trace channels and the exact contact events.

``simulate(record=...)``, ``simulate_batch(record=...)`` and ``scan(record=...)`` take it; the old keyword
``events=True`` builds it, with a DeprecationWarning, and gives the same throws bit for bit; a batch or a scan
asked for trace channels is refused in one line; a scan folder written before (its definition stores a bare
``events``) resumes.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import dicetrace
from dicetrace import saving
from dicetrace.core import kernels
from dicetrace.core.loop import ENERGY_COLS, FORCE_COLS, STATE_COLS
from dicetrace.ics import Grid
from dicetrace.params import make_config
from dicetrace.saving import Record
from dicetrace.scan import ScanDefinition, read_manifest, read_scan, scan
from dicetrace.simulate import BatchResult, simulate, simulate_batch

PHYSICAL = make_config("physical", t_max_s=1.0)
#: Two `physical` throws with many contact events (the CLI test's), in the preset's convention.
ICS = np.array([[10.0, 0.0, 0.0, 300.0, 0.0, 0.0], [-40.0, 25.0, 30.0, 900.0, -1500.0, 400.0]])
#: A folder the code before the request wrote: ``scan(OLD_GRID, ..., chunk=2, events=True, max_chunks=1)``.
OLD_FOLDER = Path(__file__).parent / "data" / "scan_events_old"
OLD_GRID = Grid("seed", "home", 2)
DEPRECATED = r"events=\.\.\.\) is deprecated .*record=Record\.events_only\(\)"


@pytest.fixture
def no_deprecated_events():
    """Turns the ``events=`` DeprecationWarning into an error within the test (other warnings stay as they are)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*events=.*deprecated", category=DeprecationWarning)
        yield


# -- the request ---------------------------------------------------------------------------------------------------


def test_record_holds_the_trace_channels_and_the_events():
    assert (Record().states, Record().energy, Record().forces, Record().events) == (True, True, False, False)
    assert Record().channels == ("states", "energy") and Record().traces
    ev = Record.events_only()
    assert ev == Record(states=False, energy=False, events=True)
    assert ev.channels == () and not ev.traces and ev.events
    assert Record(states=True, forces=True, events=True).channels == ("states", "energy", "forces")
    with pytest.raises(ValueError, match=r"Record\(\) asks for nothing: request states, energy, forces or events"):
        Record(states=False, energy=False)
    with pytest.raises(TypeError, match=r"Record\(events=\.\.\.\) must be True or False, got 'yes'"):
        Record(events="yes")
    with pytest.raises(dataclasses.FrozenInstanceError):
        ev.events = False
    assert dicetrace.Record is Record
    from dicetrace import simulate as simulate_module

    assert simulate_module.Record is Record


def test_the_request_imports_without_numba():
    code = "import sys, dicetrace; dicetrace.Record.events_only(); print('numba' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


def test_the_outputs_are_made_from_the_request():
    """One function per structure makes a loop's outputs from the request: event times only where it asks for
    events, trace rows only for the channels it asks for; a batch throw's loop outputs are views of the batch's."""
    out = kernels.roll_out_for(64, Record(states=True, energy=False, forces=True, events=True), rows=11)
    assert (out.sets.shape, out.set_steps.shape, out.ev_times.shape) == ((64,), (64,), (64,))
    assert (out.tr_state.shape, out.tr_force.shape, out.tr_energy.shape) == ((11, STATE_COLS), (11, FORCE_COLS),
                                                                          (0, ENERGY_COLS))
    plain = kernels.roll_out_for(64)
    assert plain.ev_times.shape == (0,) and plain.tr_state.shape == (0, STATE_COLS)
    assert kernels.roll_out_for(8, Record.events_only()).tr_state.shape == (0, STATE_COLS)
    b = kernels.batch_out(5, 8, Record.events_only())
    assert (b.sets.shape, b.ev_times.shape, b.status.shape) == ((40,), (40,), (5,))
    assert kernels.batch_out(5, 8).ev_times.shape == (0,)
    t = kernels.throw_out(b, 3, 8)
    assert t.sets.shape == (8,) and np.shares_memory(t.sets, b.sets[24:32])
    assert np.shares_memory(t.ev_times, b.ev_times[24:32]) and t.tr_state.shape == (0, STATE_COLS)
    assert kernels.throw_out(kernels.batch_out(5, 8), 3, 8).ev_times.shape == (0,)


# -- simulate and simulate_batch: the request, and the old keyword as its alias ------------------------------------


def _same_roll(a, b) -> None:
    assert (a.status, a.steps, a.outcome, a.substeps) == (b.status, b.steps, b.outcome, b.substeps)
    for name in ("contact_sets", "contact_steps", "contact_times"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), strict=True)


def test_simulate_keeps_the_events_the_request_asks_for_as_the_old_keyword_did(no_deprecated_events):
    for ic in ICS:
        new = simulate(ic, config=PHYSICAL, record=Record.events_only())
        assert new.trace is None and len(new.contact_times) > 5
        with pytest.warns(DeprecationWarning, match=DEPRECATED):
            old = simulate(ic, config=PHYSICAL, events=True)
        _same_roll(new, old)
        # with trace channels beside the events: the same trace, bit for bit, and the same events
        both = simulate(ic, config=PHYSICAL, record=Record(states=True, forces=True, events=True))
        with pytest.warns(DeprecationWarning, match=DEPRECATED):
            both_old = simulate(ic, config=PHYSICAL, record=Record(states=True, forces=True), events=True)
        _same_roll(both, both_old)
        _same_roll(both, new)
        for name in ("cm_pos", "cm_vel", "L", "node_offsets", "forces"):
            np.testing.assert_array_equal(getattr(both.trace, name), getattr(both_old.trace, name))
        assert all(np.array_equal(both.trace.energy[k], both_old.trace.energy[k]) for k in both.trace.energy)
        # the throw is the one without events: only the sets differ
        plain = simulate(ic, config=PHYSICAL)
        assert (plain.status, plain.steps, plain.outcome) == (new.status, new.steps, new.outcome)
        assert plain.contact_times is None
    with pytest.warns(DeprecationWarning, match=DEPRECATED):
        off = simulate(ICS[0], config=PHYSICAL, events=False)
    _same_roll(off, simulate(ICS[0], config=PHYSICAL))


def _same_batch(a: BatchResult, b: BatchResult) -> None:
    for f in dataclasses.fields(BatchResult):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            np.testing.assert_array_equal(x, y, strict=True)
        else:
            assert x == y, f.name


@pytest.mark.parametrize("m", [3, 20], ids=["serial", "batch-kernel"])  # up to BATCH_BLOCK ICs run one by one
def test_simulate_batch_keeps_the_events_the_request_asks_for_as_the_old_keyword_did(m, no_deprecated_events):
    rng = np.random.default_rng(45)
    ics = ICS[rng.integers(0, 2, m)] * rng.uniform(0.8, 1.2, (m, 6))
    new = simulate_batch(ics, config=PHYSICAL, record=Record.events_only())
    with pytest.warns(DeprecationWarning, match=DEPRECATED):
        old = simulate_batch(ics, config=PHYSICAL, events=True)
    _same_batch(new, old)
    assert new.set_times is not None and len(new.set_times) == len(new.sets) > 5 * m
    # row by row, the single throw's events
    one = simulate(ics[m - 1], config=PHYSICAL, record=Record.events_only())
    a, b = new.set_offsets[m - 1], new.set_offsets[m]
    np.testing.assert_array_equal(new.set_times[a:b], one.contact_times)
    assert simulate_batch(ics, config=PHYSICAL, record=None).set_times is None


def test_a_batch_asked_for_trace_channels_is_refused_in_one_line():
    for record, names in ((Record(), "states, energy"), (Record(states=False, energy=False, forces=True, events=True),
                                                          "forces")):
        with pytest.raises(ValueError, match=f"simulate_batch keeps no per-step channels, and record asks for {names}: "
                                             r"pass record=Record\.events_only\(\)") as exc:
            simulate_batch(ICS, config=PHYSICAL, record=record)
        assert "\n" not in str(exc.value)
    with pytest.raises(TypeError, match="record must be a dicetrace.Record or None, not str"):
        simulate_batch(ICS, config=PHYSICAL, record="events")
    with pytest.raises(ValueError, match=r"record=Record\(events=True\): integrator 'semi-implicit-euler' has no exact"):
        simulate(ICS[0], preset="seed", record=Record.events_only())
    with pytest.raises(ValueError, match=r"record=Record\(events=True\): integrator 'rk4' has no exact"):
        simulate_batch(ICS, preset="physical", integrator="rk4", record=Record.events_only())


# -- scans ---------------------------------------------------------------------------------------------------------


def test_a_scan_takes_the_request_and_refuses_trace_channels(tmp_path, no_deprecated_events):
    assert ScanDefinition(OLD_GRID, PHYSICAL, 2, events=True).record == Record.events_only()
    assert ScanDefinition(OLD_GRID, PHYSICAL, 2).record is None
    with pytest.raises(ValueError, match="scan keeps no per-step channels, and record asks for states, energy"):
        scan(OLD_GRID, tmp_path / "a", config=PHYSICAL, chunk=2, record=Record())
    with pytest.raises(ValueError, match="not both"):
        scan(ScanDefinition(OLD_GRID, PHYSICAL, 2), record=Record.events_only())
    assert not any(tmp_path.iterdir())
    table = scan(OLD_GRID, config=PHYSICAL, chunk=2, record=Record.events_only())
    with pytest.warns(DeprecationWarning, match=DEPRECATED):
        old = scan(OLD_GRID, config=PHYSICAL, chunk=2, events=True)
    assert table.equals(old) and "contact_times_s" in table.column_names


def test_a_folder_written_before_the_request_resumes(tmp_path, no_deprecated_events):
    """The old code's events scan, one chunk of two written (its definition a bare ``"events": true``): resumed
    with the request, the chunk written is kept and the other computed, and the rows are the batch's bit for bit."""
    folder = tmp_path / "old"
    shutil.copytree(OLD_FOLDER, folder)
    before = (folder / "rolls" / "part-000000.parquet").read_bytes()
    cfg = make_config("physical")
    assert read_manifest(folder)["definition"]["events"] is True
    report = scan(OLD_GRID, folder, config=cfg, chunk=2, record=Record.events_only())
    assert (report.chunks_skipped, report.chunks_computed) == (1, 1)
    assert (folder / "rolls" / "part-000000.parquet").read_bytes() == before
    df = read_scan(folder)
    blk = OLD_GRID.block(0, OLD_GRID.size)
    want = simulate_batch(blk.ics, config=cfg, l_convention=OLD_GRID.slice.l_convention, record=Record.events_only())
    for i in range(OLD_GRID.size):
        a, b = want.set_offsets[i], want.set_offsets[i + 1]
        np.testing.assert_array_equal(df["contact_sets"][i], want.sets[a:b])
        np.testing.assert_array_equal(df["contact_times_s"][i], want.set_times[a:b])
    np.testing.assert_array_equal(df["steps"], want.steps)


def test_the_cli_events_flags_build_the_request(tmp_path, dicetrace_cli, no_deprecated_events):
    """``--events`` is unchanged at the command line and goes in as the request (no deprecated keyword inside):
    ``simulate`` gives the API's events; ``scan`` resumes the old code's folder."""
    ic = ",".join(map(repr, ICS[0].tolist()))
    res = dicetrace_cli("simulate", "--ic", ic, "--preset", "physical", "--t-max", "1", "--events", "--format", "csv",
                        cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    times = next(csv.DictReader(io.StringIO(res.stdout)))["contact_times_s"]
    want = simulate(ICS[0], config=PHYSICAL, record=Record.events_only())
    assert [float(t) for t in times.split()] == want.contact_times.tolist()
    shutil.copytree(OLD_FOLDER, tmp_path / "old")
    res = dicetrace_cli("scan", "--preset", "physical", "--window", "home", "--res", "2", "--chunk", "2", "--events",
                        "--out", "old", "-q", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert len(read_scan(tmp_path / "old")) == 4


def test_the_deprecated_keyword_is_checked_as_before():
    with pytest.warns(DeprecationWarning, match=DEPRECATED), pytest.raises(ValueError, match="events must be True or False"):
        simulate(ICS[0], config=PHYSICAL, events="yes")
    with pytest.warns(DeprecationWarning, match="simulate_batch"), pytest.raises(ValueError, match="no exact contact"):
        simulate_batch(ICS, preset="seed", events=True)
    assert saving.record_with_events(None, saving.NOT_GIVEN, "x") is None
