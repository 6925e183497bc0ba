"""``dicetrace scan`` against a hostile user: one line, exit 2, nothing touched, before any work.

Every output (``--out``, ``--png``, ``--rrd``) is checked before the scan
runs; sizes are exact and refused when they cannot be numbered or stored;
an unreachable, silent or non-Dask ``--scheduler`` is one line within the
stated bound; exit codes count failures.  In-process runs (the console
script's ``run_app``) in a snapshotted folder.
"""

from __future__ import annotations

import os
import socket
import stat
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dicetrace.scan import read_manifest


HOME3 = ["--window", "home", "--res", "3"]


@pytest.fixture(scope="module")
def done_scan(tmp_path_factory) -> Path:
    """A finished scan of HOME3 (copied into each test's folder as 'done')."""
    from dicetrace.ics import Grid
    from dicetrace.scan import scan

    d = tmp_path_factory.mktemp("scans") / "done"
    scan(Grid("seed", "home", 3), d)
    return d


@pytest.fixture
def work(tmp_path, done_scan) -> Path:
    import shutil

    (tmp_path / "afile").write_text("not a folder")
    (tmp_path / "adir").mkdir()
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "mine.txt").write_text("mine")
    (tmp_path / "existing.png").write_bytes(b"an old map")
    (tmp_path / "existing.rrd").write_bytes(b"an old scan map")
    (tmp_path / "loop.png").symlink_to("loop.png")
    (tmp_path / "pts.csv").write_text("x,y\n0.05,0.05\n1e308,1e308\n")
    shutil.copytree(done_scan, tmp_path / "done")
    return tmp_path


def case(args, *names, out="x"):
    return pytest.param(list(args), names, out, id=" ".join(args) + (f" --out {out}" if out != "x" else ""))


def _refused_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now: connections are refused
    return port


BAD = [
    # outputs checked before the scan ran (items 1, 2, 5)
    case([*HOME3, "--png", "map"], "--png", "'map'", ".png"),
    case([*HOME3, "--rrd", "map"], "--rrd", "'map'", ".rrd"),
    case([*HOME3, "--rrd", "adir"], "--rrd", "'adir'", "folder"),
    case([*HOME3, "--png", "adir"], "--png", "'adir'", "folder"),
    case([*HOME3, "--png", "/proc/x.png"], "--png", "'/proc/x.png'", "'/proc'"),
    case([*HOME3, "--rrd", "/proc/x.rrd"], "--rrd", "'/proc/x.rrd'", "'/proc'"),
    case([*HOME3, "--png", "afile/m.png"], "--png", "'afile'"),
    case([*HOME3, "--rrd", "afile/m.rrd"], "--rrd", "'afile'"),
    case([*HOME3, "--png", "loop.png"], "--png", "'loop.png'"),
    case([*HOME3, "--png", "-", "--rrd", "-"], "--png", "--rrd", "standard output"),
    case([*HOME3, "--png", "existing.png", "--window", "atlantis"], "--window", "'atlantis'"),
    case(HOME3, "--out", "'afile'", "not a folder", out="afile"),
    case(HOME3, "--out", "'afile'", out="afile/sub"),
    case(HOME3, "--out", "'/proc", out="/proc/scan"),
    case(HOME3, "--out", "not empty", out="notes"),
    case(["--window", "home", "--res", "4"], "--out", "'done'", "different scan", out="done"),
    case([*HOME3, "--gamma", "1"], "--gamma", out="done"),
    # sizes (item 3)
    case(["--window", "home", "--res", "10000000000"], "--res", "100,000,000,000,000,000,000 ICs", "int64"),
    case(["--window", "home", "--res", "4000000000,1"], "--res", "int32"),
    case(["--window", "home", "--res", "100000"], "--out", "this run writes", "free"),
    case(["--window", "home", "--res", "2.5"], "--res", "'2.5'"),
    case(["--window", "home", "--res", "3,3,3"], "--res", "needs 2"),
    case(["--window", "home", "--res", "-3"], "--res", ">= 1"),
    case([*HOME3, "--chunk", "100000000"], "--chunk", "at most"),
    case(["--sample", "sobol", "--n", "2000000000", "--box", "home"], "--n", "2**30"),
    case(["--sample", "random", "--n", "5", "--box", "home", "--seed", "-1"], "--seed", "[0, 2**64)", "-1"),
    case(["--sample", "random", "--n", "0", "--box", "home"], "--n", ">= 1"),
    case(["--sample", "random", "--n", "5", "--box", "1,0"], "--box"),
    case(["--window", "1e308,1.5e308,0,1", "--res", "3"], "--window", "non-finite"),
    # one rule for windows (x1 > x0 on every axis; a grid axis of one point may be a single value), options that
    # would be ignored, and memory (issue 36, items 7 and 8)
    case(["--window", "1,1,0,1", "--res", "10"], "--window", "zero width", "'1,1,0,1'"),
    case(["--window", "0,1,1,0", "--res", "3"], "--window", "y1 > y0", "negative width"),
    case(["--window", "1,1,0,1", "--res", "3,1"], "--window", "x1 > x0"),  # one point on y: x still needs a width
    case(["--sample", "random", "--n", "5", "--box", "0,1,1,1"], "--box", "zero width"),
    case(["--slice", "seed3", "--window", "home", "--z", "0.02,0.02", "--res", "3,3,2"], "--z", "zero width"),
    case(["--slice", "seed3", "--window", "home", "--z", "0.1,0", "--res", "3"], "--z", "negative width"),
    case([*HOME3, "--z", "0,1"], "--z", "3-D"),
    case([*HOME3, "--n", "5"], "--n", "--sample"),
    case([*HOME3, "--seed", "3"], "--seed", "--sample"),
    case([*HOME3, "--box", "home"], "--box", "--sample"),
    case(["--points", "pts.csv", "--z", "0,1"], "--z", "--points"),
    case(["--window", "home", "--res", "100000", "--png", "m.png"], "--png", "10,000,000,000 ICs", "memory"),
    case(["--window", "home", "--res", "100000", "--rrd", "m.rrd"], "--rrd", "memory"),
    case([*HOME3, "--dask", "--workers", "100000"], "--workers", "memory"),
    case(["--sample", "random", "--n", "5", "--box", "-1e308,1e308,0,1"], "--box", "non-finite"),
    case(["--points", "pts.csv"], "--points", "non-finite"),
    case(["--points", "missing.csv"], "--points", "'missing.csv'"),
    case(["--points", "afile"], "--points", "'afile'"),
    # the model and the numerics (items 4, 9)
    case([*HOME3, "--dt", "auto", "--integrator", "forward-euler", "--set", "k=5e7"], "--dt auto", "k = 5e+07"),
    case([*HOME3, "--tol", "1e-5"], "--tol", "contact-adaptive"),
    case([*HOME3, "--tol-growth", "10"], "--tol-growth", "contact-adaptive"),
    case([*HOME3, "--preset", "physical", "--tol-growth", "1e4"], "--tol-growth", "[0, 1000]"),
    case([*HOME3, "--dt", "2", "--t-max", "1"], "--dt", "--t-max", "longer than the time cap"),
    case([*HOME3, "--max-chunks", "-1"], "--max-chunks", ">= 0"),
    case([*HOME3, "--set", "g=980"], "--set", "gravity g"),
    case([*HOME3, "--set", "z0_cm=0.5"], "--set", "z0_cm"),
    case([*HOME3, "--set", "k=inf"], "--set", "k"),
    case([*HOME3, "--set", "friction=coulomb"], "--set", "friction"),
    case([*HOME3, "--set", "k"], "--set", "NAME=VALUE"),
    case([*HOME3, "--set", "gamma=0.01", "--set", "gamma=0.02"], "--set gamma", "twice", "gamma=0.01", "gamma=0.02"),
    case([*HOME3, "--set", "gamma=0.01", "--set", "mu=0.5", "--set", "gamma = 0.01"], "--set gamma", "twice"),
    # Dask (items 5, 6) and the rest of the options
    case([*HOME3, "--scheduler", "tcp://x y"], "--scheduler", "'tcp://x y'"),
    case([*HOME3, "--scheduler", "tcp://127.0.0.1:99999"], "--scheduler", "99999"),
    case([*HOME3, "--scheduler", "http://127.0.0.1:8786"], "--scheduler", "http"),
    case([*HOME3, "--scheduler", "127.0.0.1"], "--scheduler", "needs a port"),
    case([*HOME3, "--scheduler", "tcp://127.0.0.1:{refused}"], "--scheduler", "refused"),
    case(["--window", "red-sea", "--res", "400", "--scheduler", "tcp://127.0.0.1:{refused}"], "--scheduler", "refused"),
    case([*HOME3, "--workers", "2"], "--workers", "--dask"),
    case([*HOME3, "--dask", "--workers", "0"], "--workers", ">= 1"),
    case([*HOME3, "--dask", "--scheduler", "tcp://127.0.0.1:1"], "--dask", "--scheduler", "not both"),
    case([*HOME3, "--wait", "-1"], "--wait", ">= 0"),
    case([*HOME3, "--wait", "nan"], "--wait"),
    case([*HOME3, "--threads", "0"], "--threads", ">= 1"),
    case([*HOME3, "--chunk", "0"], "--chunk", ">= 1"),
    case([*HOME3, "--chunk", "x"], "--chunk", "integer"),
    # an existing finished scan and existing maps are not touched by a refusal
    case([*HOME3, "--png", "map"], "--png", ".png", out="done"),
    case([*HOME3, "--rrd", "/proc/x.rrd"], "--rrd", "'/proc", out="done"),
    case([*HOME3, "--rrd", "existing.rrd", "--dt", "-1"], "--dt", "'-1'", out="done"),
    case([*HOME3, "--png", "existing.png", "--max-chunks", "-5"], "--max-chunks", out="done"),
]


@pytest.mark.parametrize("args,names,out", BAD)
def test_bad_input_is_one_line_exit_2_and_leaves_the_folder_byte_for_byte(snapshot, work, dicetrace_cli, assert_one_line_error,
                                                                          args, names, out, monkeypatch):
    import dicetrace.scan.estimate as estimate
    import dicetrace.scan.runner as runner

    def no_work(*a, **k):
        raise AssertionError("a chunk (or the estimate's probe) was computed before the input was refused")

    monkeypatch.setattr(runner, "compute_chunk", no_work)
    monkeypatch.setattr(estimate, "simulate_batch", no_work)  # every option is checked before the estimate computes
    args = [a.replace("{refused}", str(_refused_port())) for a in args]
    before = snapshot(work)
    res = dicetrace_cli("scan", *args, "--out", out, "-q", cwd=work)
    line = assert_one_line_error(res, *names)
    assert "np.float64" not in line and "Warning" not in res.stderr
    assert snapshot(work) == before


# -- item 4: --dt auto sees the overrides ---------------------------------------------------------------------


def test_dt_auto_is_chosen_for_the_overridden_stiffness(tmp_path, dicetrace_cli):
    from dicetrace.params import get_preset
    from dicetrace.stepsize import auto_dt
    from dicetrace.scan.read import read_scan, scan_definition

    res = dicetrace_cli("scan", *HOME3, "--dt", "auto", "--set", "k=5e7", "--t-max", "2", "--out", "s", "-q",
                        cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    dt = scan_definition(tmp_path / "s").config.numerics.dt_s
    stiff = get_preset("seed").with_(k=5e7)
    assert dt == auto_dt(stiff, "semi-implicit-euler", t_max_s=2.0)
    assert dt < auto_dt(get_preset("seed"), "semi-implicit-euler", t_max_s=2.0) / 5  # not k = 5·10⁵'s step
    assert not read_scan(tmp_path / "s")["status"].isin(["blow_up", "non_finite"]).any()


# -- item 9: the summary counts statuses, --strict exits 1 -----------------------------------------------------


def test_summary_counts_failures_and_strict_exits_1(tmp_path, dicetrace_cli):
    res = dicetrace_cli("scan", *HOME3, "--dt", "0.01", "--out", "s", cwd=tmp_path)
    assert res.returncode == 0  # the scan itself is complete
    assert "statuses: blow_up: 9 (100.0%)" in res.stderr
    fail_lines = [ln for ln in res.stderr.splitlines() if ln.startswith("dicetrace: numerical failure: 9 of 9 ICs")]
    assert len(fail_lines) == 1 and "blow_up: 9" in fail_lines[0]
    res = dicetrace_cli("scan", *HOME3, "--dt", "0.01", "--out", "s", "-q", "--strict", cwd=tmp_path)
    assert res.returncode == 1
    assert res.stderr.strip().splitlines() == fail_lines  # quiet: the failure line only
    ok = dicetrace_cli("scan", *HOME3, "--out", "ok", "-q", "--strict", cwd=tmp_path)
    assert ok.returncode == 0 and ok.stderr == ""


# -- item 3: the estimate, the bound and --yes --------------------------------------------------------------------


@pytest.mark.slow  # seconds (a subprocess or a long fit): the quick loop skips it, CI runs it
def test_a_long_scan_needs_yes_and_says_its_estimate(tmp_path, dicetrace_cli, monkeypatch):
    import dicetrace.commands.scan as cmd

    args = ["--window", "home", "--res", "12", "--dt", "2e-4", "--out", "s"]
    monkeypatch.setattr(cmd, "MAX_UNCONFIRMED_S", 1e-9)  # any calibrated estimate is "too long"
    res = dicetrace_cli("scan", *args, "-q", cwd=tmp_path)
    assert res.returncode == 2
    (line,) = res.stderr.strip().splitlines()
    assert "--yes" in line and "144 ICs" in line and "on disk" in line
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(cmd, "LARGE_SCAN_S", 0.0)
    res = dicetrace_cli("scan", *args, "--yes", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stderr.startswith("dicetrace: scan: 144 ICs in 1 chunks to compute (of 144): ")
    assert len(read_manifest(tmp_path / "s")["definition"]["space"]["res"]) == 2


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_estimate_scan_numbers(tmp_path):
    from dicetrace.ics import Grid
    from dicetrace.params import make_config
    from dicetrace.scan import ScanDefinition
    from dicetrace.scan.estimate import BYTES_PER_CHUNK, BYTES_PER_IC, estimate_scan

    defn = ScanDefinition(Grid("seed", "home", 100), make_config(), 1000)
    est = estimate_scan(defn, tmp_path / "new", threads=2)
    assert (est.n_ics, est.n_chunks, est.chunks_todo, est.ics_todo) == (10_000, 10, 10, 10_000)
    assert est.bytes == 10_000 * BYTES_PER_IC + 10 * BYTES_PER_CHUNK
    assert est.seconds is not None and 0 < est.seconds < 600  # calibrated: a few seconds on any machine
    part = estimate_scan(defn, tmp_path / "new", threads=2, max_chunks=3)
    assert (part.chunks_todo, part.ics_todo) == (3, 3000)
    huge = ScanDefinition(Grid("seed", "home", 100_000), make_config(), 8192)
    assert estimate_scan(huge, calibrate=False).bytes > 10**12  # 10¹⁰ ICs: a terabyte


# -- items 5, 6: Dask schedulers that are not there, silent, or not Dask ----------------------------------------


def _server(reply: bytes | None):
    """A local TCP server (127.0.0.1 only) that sends ``reply`` to every connection, or nothing (None)."""
    srv = socket.socket()
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    held = []

    def serve():
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            held.append(c)
            if reply is not None:
                try:
                    c.sendall(reply)
                except OSError:
                    pass

    threading.Thread(target=serve, daemon=True).start()
    return srv, held


@pytest.mark.parametrize("reply", [b"\xff" * 64 + b"HTTP/1.1 200 OK\r\n\r\n" + b"garbage" * 20, None],
                         ids=["garbage", "silent"])
def test_a_server_that_is_not_a_dask_scheduler_is_one_line_within_the_bound(tmp_path, dicetrace_cli,
                                                                           assert_one_line_error, monkeypatch, reply):
    pytest.importorskip("dask.distributed")
    import dicetrace.scan.dask as scan_dask

    monkeypatch.setattr(scan_dask, "DASK_CONNECT_TIMEOUT_S", 1.0)
    srv, held = _server(reply)
    try:
        t0 = time.monotonic()
        address = f"tcp://127.0.0.1:{srv.getsockname()[1]}"
        res = dicetrace_cli("scan", *HOME3, "--scheduler", address, "--out", "s", "-q", cwd=tmp_path)
        wall = time.monotonic() - t0
    finally:
        srv.close()
        for c in held:
            c.close()
    line = assert_one_line_error(res, "--scheduler", address)
    assert ("within 1 s" in line) if reply is None else ("not answer as a Dask scheduler" in line)
    assert wall < 1.0 + 3.0, f"took {wall:.1f} s for a 1 s bound"
    assert list(tmp_path.iterdir()) == []  # no scan folder: Dask is connected to before anything is written


# -- outputs that are devices, FIFOs, symlinks -----------------------------------------------------------------------


def test_maps_go_to_a_fifo_and_through_a_symlink(tmp_path, dicetrace_cli):
    fifo = tmp_path / "map.fifo"
    os.mkfifo(fifo)
    (tmp_path / "real.png").write_bytes(b"old")
    (tmp_path / "latest.png").symlink_to("real.png")
    box: dict = {}

    def reader():
        with open(fifo, "rb") as f:
            box["data"] = f.read()

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    res = dicetrace_cli("scan", *HOME3, "--out", "s", "--rrd", str(fifo), "--png", "latest.png", "-q", cwd=tmp_path)
    t.join(30)
    assert res.returncode == 0, res.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and box["data"][:4] == b"RRF2"
    assert (tmp_path / "latest.png").is_symlink() and (tmp_path / "real.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest.png", "map.fifo", "real.png", "s"]


# -- a full disk: --png, --rrd, the chunks ---------------------------------------------------------------------------


def test_maps_onto_a_full_disk_are_one_line_and_keep_the_old_maps(snapshot, fill_fs, tmp_path, tmpfs, dicetrace_cli, assert_one_line_error):
    (tmpfs / "m.png").write_bytes(b"old map")
    (tmpfs / "m.rrd").write_bytes(b"old scan map")
    fill_fs(tmpfs)
    before = snapshot(tmpfs)
    res = dicetrace_cli("scan", *HOME3, "--out", "s", "--png", str(tmpfs / "m.png"), "--rrd", str(tmpfs / "m.rrd"), "-q",
                        cwd=tmp_path)
    assert_one_line_error(res, "No space left on device")
    assert snapshot(tmpfs) == before  # both old maps whole, no temporary
    assert (tmp_path / "s" / "_scan.parquet").exists()  # the scan itself is complete and kept


def test_chunks_onto_a_full_disk_are_one_line_and_resume_afterwards(tmp_path, tmpfs, dicetrace_cli,
                                                                    assert_one_line_error, monkeypatch):
    """The estimate would refuse; with it fooled, the writes themselves hit ENOSPC: one line, finished chunks kept."""
    import dicetrace.scan.estimate as estimate
    from dicetrace.ics import Grid
    from dicetrace.scan import read_scan, scan

    monkeypatch.setattr(estimate, "BYTES_PER_IC", 0)
    monkeypatch.setattr(estimate, "BYTES_PER_CHUNK", 0)
    args = ["--window", "home", "--res", "9", "--chunk", "3", "-q"]
    res = dicetrace_cli("scan", *args, "--out", str(tmpfs / "s"), cwd=tmp_path)
    line = assert_one_line_error(res, "No space left on device", "part-")
    assert "re-run" in line
    files = sorted(p.name for p in (tmpfs / "s").rglob("*"))
    assert not [f for f in files if f.endswith(".tmp")]
    n = len(list((tmpfs / "s" / "rolls").glob("part-*.parquet")))
    assert 0 < n < 27
    from dicetrace.scan.folder import read_chunk_log

    logged = read_chunk_log(tmpfs / "s")  # the chunks whose log entry the full disk let through
    assert len(logged) <= n and len(read_scan(tmpfs / "s")) == 3 * len(logged)  # readers read only those, verified
    # move it to a roomy disk and resume: exactly one row per IC, as a single run
    import shutil

    shutil.copytree(tmpfs / "s", tmp_path / "s")
    res = dicetrace_cli("scan", *args, "--out", str(tmp_path / "s"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    df = read_scan(tmp_path / "s")
    assert (df["ic_id"] == np.arange(81)).all()
    want = scan(Grid("seed", "home", 9), chunk=3).to_pandas()
    assert df.drop(columns=[]).reset_index(drop=True).equals(want.reset_index(drop=True))


def test_rrd_onto_a_full_disk_does_not_hang(tmp_path, tmpfs, fill_fs, dicetrace_cli):
    """The issue's hang (rerun's writer stuck on a full disk, a .m.rrd.tmp left): run with a deadline."""
    fill_fs(tmpfs)
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("res", dicetrace_cli(
        "scan", *HOME3, "--out", str(tmp_path / "s"), "--rrd", str(tmpfs / "m.rrd"), "-q", cwd=tmp_path)), daemon=True)
    t.start()
    t.join(120)
    assert not t.is_alive(), "scan --rrd onto a full disk hangs"
    res = box["res"]
    assert res.returncode == 2, res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert "No space left on device" in line and "Traceback" not in res.stderr
    assert sorted(p.name for p in tmpfs.iterdir()) == ["filler"]


# -- standard error decides nothing (issue 47 F3) ----------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("stderr", ["closed", pytest.param("/dev/full", marks=pytest.mark.long)])
def test_a_scan_writes_its_data_and_exits_0_whatever_standard_error_is(tmp_path, stderr):
    """With standard error closed (``2>&-``: once exit 70, nothing written) or on /dev/full (once the data, then
    exit 2), a scan writes its folder, puts nothing on standard output, and exits 0: what it says there decides
    nothing.  Its summary lines, a device line and a warning all try to reach it."""
    import subprocess
    import sys

    from dicetrace.ics import Grid
    from dicetrace.scan import read_scan, scan

    if stderr == "/dev/full" and not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    scan(Grid("seed", "home", 3), tmp_path / "s", chunk=4, max_chunks=1)
    (tmp_path / "s" / "rolls" / "part-000000.parquet").write_bytes(b"PAR1 damaged PAR1")  # a warning to say
    args = [sys.executable, "-m", "dicetrace", "scan", "--window", "home", "--res", "3", "--chunk", "4", "--out", "s",
            "--device", "auto", "--png", "m.png"]
    if stderr == "closed":
        res = subprocess.run(["sh", "-c", '"$0" "$@" 2>&-', *args], cwd=tmp_path, capture_output=True, text=True,
                             timeout=300)
    else:
        with open("/dev/full", "w") as full:
            res = subprocess.run(args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=full, text=True, timeout=300)
    assert res.returncode == 0, res
    assert res.stdout == ""
    got = read_scan(tmp_path / "s")
    want = scan(Grid("seed", "home", 3), chunk=4).to_pandas()
    assert got[["ic_id", "outcome", "steps", "contact_sequence"]].equals(want[["ic_id", "outcome", "steps",
                                                                                "contact_sequence"]])
    assert (tmp_path / "m.png").read_bytes().startswith(b"\x89PNG")
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [".dicetrace-scan.lock", "_scan.parquet", "rolls"]


# -- property --------------------------------------------------------------------------------------------------------

_VALUES = {
    "--window": ["home", "party", "0,0.1,0,0.1", "atlantis", "1,0", "1e308,1e308,0,1"],
    "--res": ["2", "3", "2,3", "0", "-1", "a", "1e3", "10000000000", "3,3,3"],
    "--sample": ["random", "sobol", "halton"],
    "--n": ["3", "0", "-1", "2000000000"],
    "--box": ["home", "0,0.1,0,0.1", "x"],
    "--seed": ["0", "7", "-1"],
    "--slice": ["seed", "seed3", "moon"],
    "--z": ["0,0.1", "0", "x"],
    "--dt": ["0.001", "auto", "0", "-1", "nan", "2", "fast"],
    "--t-max": ["0.5", "1", "0", "inf", "1e12"],
    "--tol": ["1e-6", "0", "x"],
    "--integrator": ["semi-implicit-euler", "rk4", "magic"],
    "--chunk": ["2", "1000", "0", "-5"],
    "--max-chunks": ["0", "1", "-1"],
    "--png": ["m.png", "m", "adir", "/proc/m.png"],
    "--rrd": ["m.rrd", "m", "afile/m.rrd"],
    "--out": ["s", "afile", "notes", "done", "/proc/s"],
    "--set": ["k=5e5", "g=980", "gamma=-1", "mu=x"],
    "--wait": ["0", "-1"],
}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(sorted(_VALUES)), st.integers(0, 99), max_size=6))
def test_random_options_never_trace_back(work, dicetrace_cli, opts):
    import shutil

    args = []
    for opt, i in sorted(opts.items()):
        args += [opt, _VALUES[opt][i % len(_VALUES[opt])]]
    given_ = dict(zip(args[::2], args[1::2]))
    if "--out" not in given_:
        args += ["--out", "s"]
        given_["--out"] = "s"
    shutil.rmtree(work / "s", ignore_errors=True)
    for name in ("m.png", "m.rrd"):
        (work / name).unlink(missing_ok=True)
    res = dicetrace_cli("scan", *args, "-q", cwd=work)
    assert "Traceback" not in res.stderr and "internal error" not in res.stderr, (args, res.stderr)
    assert res.returncode in (0, 2), (args, res.returncode, res.stderr)
    if res.returncode == 2:
        (line,) = res.stderr.strip().splitlines()
        assert line.startswith("dicetrace: error: ")
    else:
        assert (work / given_["--out"] / "_scan.parquet").is_file(), (args, res.stderr)
        for opt in ("--png", "--rrd"):
            if opt in given_:
                assert (work / given_[opt]).is_file(), (args, res.stderr)
