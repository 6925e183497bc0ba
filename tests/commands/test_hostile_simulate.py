"""``dicetrace simulate`` against a hostile user: every malformed input is one line, exit 2, nothing touched.

Each bad case runs in-process (the console script's ``run_app``) in a folder
holding a file, a folder, an existing output, a symlink loop and friends;
the folder is snapshotted (names, types, bytes, modes, link targets) before
and after and must be byte-for-byte the same.  Then the outputs the issue
names: a character device (a node made in tmp_path, never the real /dev),
a FIFO, symlinks, ``-``, a closed and a full standard output, a full disk
(a small tmpfs as root, an injected ENOSPC elsewhere), and a property-based
test over random option values.
"""

from __future__ import annotations

import errno
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

IC = "14.08,11.46,9.87,13.8,122.8,15.5"  # the IC (settles in 527 steps)




@pytest.fixture
def work(tmp_path) -> Path:
    (tmp_path / "afile").write_text("not a folder")
    (tmp_path / "adir").mkdir()
    (tmp_path / "adir" / "inner.txt").write_text("inside")
    (tmp_path / "existing.csv").write_text("keep me\n")
    (tmp_path / "loop").symlink_to("loop")
    (tmp_path / "dirlink").symlink_to("adir")
    (tmp_path / "ok.csv").write_text("x,y\n1.65,3.9\n")
    (tmp_path / "huge.csv").write_text("x,y\n1.65,3.9\n1e308,1e308\n")
    (tmp_path / "inf.csv").write_text("vx,vy,vz,Lx,Ly,Lz\n1,2,3,4,5,1e400\n")
    (tmp_path / "binary.csv").write_bytes(b"\xff\xfe\x00garbage\x80\x81")
    return tmp_path


def case(args, *names):
    return pytest.param(list(args), names, id=" ".join(args) or "no-args")


BAD = [
    # outputs (item 1, 2): folders, files in the way, unwritable places, symlink loops: refused before any work
    case(["--ic", IC, "--out", "adir"], "--out", "'adir'", "folder"),
    case(["--ic", IC, "--out", "dirlink"], "--out", "'dirlink'", "folder"),
    case(["--ic", IC, "--out", "afile/x.csv"], "--out", "'afile'", "not a folder"),
    case(["--ic", IC, "--out", "afile/deeper/x.csv"], "--out", "'afile'"),
    case(["--ic", IC, "--out", "/proc/x.csv"], "--out", "'/proc/x.csv'", "'/proc'"),
    case(["--ic", IC, "--out", "/proc/new/deeper/x.csv"], "--out", "'/proc'"),
    case(["--ic", IC, "--out", "loop"], "--out", "'loop'"),
    case(["--ic", IC, "--out", ""], "--out", "folder"),
    case(["--ic", IC, "--out", "existing.csv", "--format", "xml"], "--format", "'xml'"),
    # numbers that are no step, no cap, or no tolerance (items 3, 9)
    case(["--ic", IC, "--dt", "2", "--t-max", "1"], "--dt", "--t-max", "longer than the time cap"),
    case(["--ic", IC, "--dt", "1e-300"], "--t-max", "--dt", "too large"),
    case(["--ic", IC, "--t-max", "1e300"], "--t-max", "--dt", "too large"),
    case(["--ic", IC, "--t-max", "1e-300"], "--t-max", "--dt 0.001 (the default)", "longer than the time cap"),
    case(["--ic", IC, "--dt", "0x10"], "--dt", "'0x10'"),
    case(["--ic", IC, "--dt", " "], "--dt"),
    case(["--ic", IC, "--dt", "-0"], "--dt", "'-0'"),
    case(["--ic", IC, "--t-max", "nan"], "--t-max", "'nan'"),
    case(["--ic", IC, "--tol", "1e-5"], "--tol", "contact-adaptive", "semi-implicit-euler"),
    case(["--ic", IC, "--integrator", "rk4", "--tol", "1e-5"], "--tol", "rk4"),
    case(["--ic", IC, "--preset", "physical", "--tol", "1e-20"], "--tol", "[1e-14, 1)"),
    case(["--ic", IC, "--tol-growth", "10"], "--tol-growth", "contact-adaptive", "semi-implicit-euler"),
    case(["--ic", IC, "--preset", "physical", "--tol-growth", "-1"], "--tol-growth", "[0, 1000]", "'-1'"),
    case(["--ic", IC, "--preset", "physical", "--tol-growth", "inf"], "--tol-growth", "'inf'"),
    case(["--ic", IC, "--preset", "physical", "--tol-growth", "fast"], "--tol-growth", "'fast'"),
    case(["--ic", IC, "--integrator", "RK4"], "--integrator", "'RK4'"),
    case(["--ic", IC, "--preset", ""], "--preset", "''"),
    # ICs: overflow is one line (no numpy warning before it), every source names itself
    case(["--slice", "seed", "--at", "1e308,1e308"], "--at", "non-finite", "too large"),
    case(["--slice", "seed3", "--at", "1e308,1,1"], "--at", "non-finite"),
    case(["--slice", "seed3", "--at", "1,2,3,4"], "--at", "got 4"),
    case(["--slice", "seed-ortho", "--at", "1"], "--at", "X,Y"),
    case(["--slice", "pluto", "--at", "1,2"], "--slice", "'pluto'"),
    case(["--ic", "1e300,1e300,1e300,1e300,1e300,1e300", "--dt", "auto"], "--dt auto", "too fast"),
    case(["--ic", "1,2,3,4,5,6,7"], "--ic", "got 7"),
    case(["--ic", ""], "--ic", "''"),
    case(["--ic", "1,2,3,4,5,-inf"], "--ic", "non-finite"),
    case(["--ic", IC, "--slice", "seed"], "--ic", "--slice", "not both"),
    case(["--ics", "ok.csv", "--ic", IC], "--ics", "--ic", "one source"),
    case(["--ics", "huge.csv", "--slice", "seed"], "'huge.csv'", "non-finite"),
    case(["--ics", "inf.csv"], "'inf.csv'", "line 2", "not finite"),
    case(["--ics", "binary.csv"], "'binary.csv'", "UTF-8"),
    case(["--ics", "/dev/null"], "'/dev/null'", "empty"),
    case(["--ics", "adir"], "'adir'", "folder"),
    case(["--ics", "afile"], "'afile'", "no rows"),
    case(["--ics", "loop"], "'loop'"),
    case(["--ics", "ok.csv"], "'ok.csv'", "--slice seed"),
    # an existing output is not touched by a refusal
    case(["--ic", "nan,1,2,3,4,5", "--out", "existing.csv"], "--ic", "non-finite"),
    case(["--ic", IC, "--dt", "-1", "--out", "existing.csv"], "--dt", "'-1'"),
    case(["--ic", IC, "--bogus", "--out", "existing.csv"], "--bogus"),
]


@pytest.mark.parametrize("args,names", BAD)
def test_bad_input_is_one_line_exit_2_and_leaves_the_folder_byte_for_byte(snapshot, work, dicetrace_cli, assert_one_line_error,
                                                                          args, names):
    before = snapshot(work)
    res = dicetrace_cli("simulate", *args, cwd=work)
    assert_one_line_error(res, *names)
    assert "Warning" not in res.stderr
    assert snapshot(work) == before


# -- what item 1 asks of outputs: devices and FIFOs written directly, symlinks followed, '-' ------------------


def _devnull_still_a_char_device() -> None:
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode), "/dev/null is no longer a character device"


@pytest.fixture
def char_device(tmp_path):
    """A character device node in tmp_path with /dev/null's numbers (root only): the real /dev is never written."""
    st_ = os.stat("/dev/null")  # read-only: only its device numbers
    node = tmp_path / "nulldev"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, st_.st_rdev)
    except (PermissionError, OSError) as e:
        pytest.skip(f"cannot make a device node here: {e}")
    yield node
    _devnull_still_a_char_device()


@pytest.fixture
def full_device(tmp_path):
    """A character device in tmp_path with /dev/full's numbers: every write fails with ENOSPC (root only)."""
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    node = tmp_path / "fulldev"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, os.stat("/dev/full").st_rdev)
    except (PermissionError, OSError) as e:
        pytest.skip(f"cannot make a device node here: {e}")
    yield node
    _devnull_still_a_char_device()


def test_a_character_device_is_written_not_replaced(char_device, dicetrace_cli):
    res = dicetrace_cli("simulate", "--ic", IC, "--out", str(char_device), "--format", "csv", cwd=char_device.parent)
    assert res.returncode == 0, res.stderr
    assert stat.S_ISCHR(os.lstat(char_device).st_mode)  # still the device, not a regular file
    assert sorted(p.name for p in char_device.parent.iterdir()) == ["nulldev"]  # no temporary beside it


def test_a_full_device_is_one_line_exit_2(full_device, dicetrace_cli, assert_one_line_error):
    res = dicetrace_cli("simulate", "--ic", IC, "--out", str(full_device), cwd=full_device.parent)
    assert_one_line_error(res, f"'{full_device}'", "No space left on device")
    assert stat.S_ISCHR(os.lstat(full_device).st_mode)
    assert sorted(p.name for p in full_device.parent.iterdir()) == ["fulldev"]


def _read_fifo(path: Path, box: dict) -> threading.Thread:
    def reader():
        with open(path, "rb") as f:
            box["data"] = f.read()

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    return t


def test_a_fifo_is_written_not_replaced(tmp_path, dicetrace_cli):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    box: dict = {}
    t = _read_fifo(fifo, box)
    res = dicetrace_cli("simulate", "--ic", IC, "--out", str(fifo), "--format", "csv", cwd=tmp_path)
    t.join(30)
    assert res.returncode == 0, res.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    text = box["data"].decode()
    assert text.startswith("ic_id,vx,vy,vz,Lx,Ly,Lz,outcome") and ",3,527," in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_a_fifo_nobody_reads_fails_within_the_stated_bound(tmp_path, dicetrace_cli, assert_one_line_error, monkeypatch):
    import dicetrace.sinks._common as common

    monkeypatch.setattr(common, "STREAM_WAIT_S", 0.3)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    res = dicetrace_cli("simulate", "--ic", IC, "--out", str(fifo), cwd=tmp_path)
    assert_one_line_error(res, f"'{fifo}'", "within 0.3 s")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_symlink_is_followed_to_its_target(tmp_path, dicetrace_cli):
    (tmp_path / "target.csv").write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to("target.csv")
    dangling = tmp_path / "dangling.csv"
    dangling.symlink_to("made/later.csv")  # into a folder that does not exist yet
    for out in (link, dangling):
        res = dicetrace_cli("simulate", "--ic", IC, "--out", str(out), "--format", "csv", cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert out.is_symlink()
    assert (tmp_path / "target.csv").read_text().startswith("ic_id,")
    assert (tmp_path / "made" / "later.csv").read_text().startswith("ic_id,")
    assert os.readlink(link) == "target.csv" and os.readlink(dangling) == "made/later.csv"


def test_dash_is_standard_output(tmp_path, dicetrace_cli):
    res = dicetrace_cli("simulate", "--ic", IC, "--out", "-", "--format", "csv", cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.startswith("ic_id,") and res.stderr == ""
    assert list(tmp_path.iterdir()) == []


def _run_with_stdout(stdout, args, tmp_path, monkeypatch, capsys):
    """Run ``dicetrace ARGS`` in-process with ``sys.stdout`` replaced (None: what Python sets when fd 1 is closed)."""
    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["dicetrace", *args])
    monkeypatch.setattr(sys, "stdout", stdout)
    monkeypatch.setattr("dicetrace.commands._common._silence_stdout", lambda: None)  # leave the test's fd 1 alone
    with pytest.raises(SystemExit) as exc:
        run_app(app)
    return exc.value.code, capsys.readouterr().err


def test_a_closed_standard_output_is_one_line(tmp_path, monkeypatch, capsys):
    """The shell's ``>&-``: Python starts with sys.stdout None; refused before any work."""
    code, err = _run_with_stdout(None, ["simulate", "--ic", IC], tmp_path, monkeypatch, capsys)
    assert code == 2 and err == "dicetrace: error: standard output is closed: give --out FILE\n"


def test_a_full_standard_output_is_one_line(tmp_path, full_device, monkeypatch, capsys):
    """``> /dev/full`` (a node in tmp_path with its numbers): the write fails at the end, in one line."""
    out = open(full_device, "w")
    try:
        code, err = _run_with_stdout(out, ["simulate", "--ic", IC], tmp_path, monkeypatch, capsys)
    finally:
        try:
            out.close()
        except OSError:  # the rows still buffered cannot be flushed either
            pass
    assert code == 2 and err == "dicetrace: error: cannot write standard output: No space left on device\n"


@pytest.mark.slow
def test_a_closed_standard_output_in_a_real_process(tmp_path):
    closed = subprocess.run(
        [sys.executable, "-c", "import os, runpy, sys; os.close(1); sys.argv = ['dicetrace', 'simulate', '--ic', "
         f"'{IC}']; runpy.run_module('dicetrace.cli', run_name='__main__')"],
        stderr=subprocess.PIPE, text=True, timeout=120, cwd=tmp_path,
    )
    assert closed.returncode == 2, closed.stderr
    assert closed.stderr == "dicetrace: error: standard output is closed: give --out FILE\n"


# -- a full disk --------------------------------------------------------------------------------------------


@pytest.fixture
def full_disk(tmp_path, monkeypatch, mount_small_tmpfs, fill_fs):
    """A folder on a full file system: a 64 KiB tmpfs, filled up (as root), else every write there fails with ENOSPC."""
    d = tmp_path / "full"
    d.mkdir()
    if mount_small_tmpfs(d):
        (d / "existing.csv").write_text("keep me\n")
        fill_fs(d)
    else:  # inject: any write through the checked destinations in that folder fails like a full disk
        import dicetrace.sinks._common as common

        (d / "existing.csv").write_text("keep me\n")
        real = common._fsync

        def enospc(path):
            if Path(path).parent == d:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return real(path)

        monkeypatch.setattr(common, "_fsync", enospc)
    return d


def test_a_full_disk_is_one_line_and_keeps_the_existing_output(snapshot, full_disk, dicetrace_cli, assert_one_line_error):
    before = snapshot(full_disk)
    res = dicetrace_cli("simulate", "--ics", str(Path(__file__).parents[1] / "data" / "reference" / "writeup_points.csv"),
                        "--slice", "seed", "--format", "json", "--out", str(full_disk / "existing.csv"), cwd=full_disk)
    assert_one_line_error(res, "--out", f"'{full_disk / 'existing.csv'}'", "No space left on device")
    assert snapshot(full_disk) == before  # the old file whole, no temporary left


# -- property: random option values never give a traceback, and exit 0 always leaves the file -----------------

_VALUES = {
    "--ic": [IC, "1,2,3,4,5,6", "0,0,0,0,0,0", "1,2,3", "nan,1,2,3,4,5", "1e308,1e308,1e308,1e308,1e308,1e308", "", "a"],
    "--slice": ["seed", "seed3", "seed-ortho", "moon", ""],
    "--at": ["1.65,3.9", "0.05,0.05,0.01", "1", "1e308,1e308", "x,y", ""],
    "--preset": ["seed", "physical", "moon"],
    "--integrator": ["semi-implicit-euler", "verlet", "rk4", "contact-adaptive", "magic"],
    "--dt": ["0.001", "0.002", "auto", "0", "-1", "nan", "2", "1e-300", "fast"],
    "--t-max": ["0.3", "1", "0", "-1", "inf", "1e12", "x"],
    "--tol": ["1e-6", "1e-3", "0", "1", "1e-300", "x"],
    "--tol-growth": ["10", "0", "-1", "nan", "x"],
    "--format": ["table", "csv", "json", "xml"],
    "--out": ["out.csv", "sub/out.json", "adir", "afile/x", "/proc/x", "-", "loop"],
}


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(sorted(_VALUES)), st.integers(0, 99), max_size=5))
def test_random_options_never_trace_back(work, dicetrace_cli, opts):
    args = []
    for opt, i in sorted(opts.items()):
        args += [opt, _VALUES[opt][i % len(_VALUES[opt])]]
    out = dict(zip(args[::2], args[1::2])).get("--out")
    for name in ("out.csv", "sub/out.json"):  # examples share the folder: start without the outputs
        (work / name).unlink(missing_ok=True)
    res = dicetrace_cli("simulate", *args, cwd=work)
    assert "Traceback" not in res.stderr and "internal error" not in res.stderr, (args, res.stderr)
    assert res.returncode in (0, 1, 2), (args, res.returncode, res.stderr)
    if res.returncode == 2:
        (line,) = res.stderr.strip().splitlines()
        assert line.startswith("dicetrace: error: ")
    if res.returncode in (0, 1) and out not in (None, "-"):
        assert (work / out).is_file(), (args, res.stderr)
