"""``dicetrace analyze`` (every study, the integrator studies included), and the aliases ``accuracy`` and
``stability``, against a hostile user: every option is checked first.

Each bad value is one line on stderr naming its option (``--res``, ``--tol``, ...) and exit code 2, before
the command touches the disk or computes: the output folder is not created and the working folder is
byte-for-byte the same.  The studies themselves are replaced by sentinels that fail the test, so that a value
that slips through is seen at once instead of starting a study.  Sizes that will not fit in memory
(``analyze --res``, ``accuracy --n``) are refused from an estimate, before anything is allocated.
"""

from __future__ import annotations

from pathlib import Path

import pytest

OUT = "OUT"


class _Started(Exception):
    """A study was started: the options were not all checked first."""


@pytest.fixture
def no_work(monkeypatch):
    """Replace every study entry point by a sentinel that records its call and raises :class:`_Started`."""
    calls: list[str] = []

    def sentinel(name):
        def started(*args, **kwargs):
            calls.append(name)
            raise _Started(name)
        return started

    monkeypatch.setattr("dicetrace.studies.runner.run", sentinel("analyze"))
    monkeypatch.setattr("dicetrace.studies.study_accuracy.study", sentinel("accuracy"))
    monkeypatch.setattr("dicetrace.studies.study_stability.stability_map", sentinel("stability"))
    monkeypatch.setattr("dicetrace.studies.study_friction.study", sentinel("friction"))
    return calls


@pytest.fixture
def work(tmp_path) -> Path:
    (tmp_path / "afile").write_text("not a folder")
    (tmp_path / "results-without-report").mkdir()
    return tmp_path


def case(args, *names):
    return pytest.param(list(args), names, id=" ".join(args))


BAD = [
    # analyze (issue 36 item 7): the reproducers, then the class
    case(["analyze", "cells", "--res", "100000"], "--res", "memory"),
    case(["analyze", "cells", "--quick", "--res", "100000"], "--res", "memory"),
    case(["analyze", "animation", "--quick", "--res", "20000"], "--res", "memory"),
    case(["analyze", "all", "--res", str(10**12)], "--res", "memory"),
    case(["analyze", "cells", "--res", "2"], "--res"),
    case(["analyze", "cells", "--res", "0"], "--res"),
    case(["analyze", "cells", "--res", "-5"], "--res"),
    case(["analyze", "cells", "--res", "1e5"], "--res"),
    case(["analyze", "converged", "--tol", "nan"], "--tol"),
    case(["analyze", "converged", "--quick", "--tol", "nan"], "--tol"),
    case(["analyze", "converged", "--tol", "inf"], "--tol"),
    case(["analyze", "converged", "--tol", "-inf"], "--tol"),
    case(["analyze", "converged", "--tol", "0"], "--tol"),
    case(["analyze", "converged", "--tol", "-1e-6"], "--tol"),
    case(["analyze", "converged", "--tol", "1"], "--tol"),
    case(["analyze", "converged", "--tol", "1e-300"], "--tol"),
    case(["analyze", "converged", "--tol", "small"], "--tol"),
    case(["analyze", "converged", "--integrator", "nope"], "--integrator", "nope"),
    case(["analyze", "converged", "--quick", "--integrator", "nope"], "--integrator"),
    case(["analyze", "converged", "--integrator", ""], "--integrator"),
    case(["analyze", "cells", "--integrator", "RK4"], "--integrator"),
    case(["analyze", "cells", "--seed", "-1"], "--seed"),
    case(["analyze", "cells", "--quick", "--seed", "-1"], "--seed"),
    case(["analyze", "cells", "--seed", str(2**64)], "--seed"),
    case(["analyze", "cells", "--seed", "1.5"], "--seed"),
    case(["analyze", "nonsense"], "unknown study", "nonsense"),
    case(["analyze", "z"], "unknown study"),  # no study has the letter z
    case(["analyze"], "name the studies"),
    case(["analyze", "--report-only", "--quick"], "--quick", "--report-only"),
    case(["analyze", "--report-only", "--res", "9"], "--res", "--report-only"),
    case(["analyze", "--report-only", "--seed", "3"], "--seed", "--report-only"),
    case(["analyze", "--report-only", "cells"], "--report-only"),
    case(["analyze", "--report-only"], "--out", "results/"),
    # accuracy (items 7 and 8): sizes, the window (one parser, zero width refused), seeds, names
    case(["accuracy", "--n", "1000000000"], "--n", "memory"),
    case(["accuracy", "--quick", "--n", str(10**15)], "--n", "memory"),
    case(["accuracy", "--n", "1"], "--n"),
    case(["accuracy", "--n", "0"], "--n"),
    case(["accuracy", "--n", "-3"], "--n"),
    case(["accuracy", "--window", "1,1,0,1"], "--window"),
    case(["accuracy", "--quick", "--window", "0,1,2,2"], "--window"),
    case(["accuracy", "--window", "1,0,0,1"], "--window"),
    case(["accuracy", "--window", "0,1,0,nan"], "--window"),
    case(["accuracy", "--window", "0,1,0"], "--window"),
    case(["accuracy", "--window", "nope"], "--window", "nope"),
    case(["accuracy", "--seed", "-1"], "--seed"),
    case(["accuracy", "--seed", str(2**64)], "--seed"),
    case(["accuracy", "--threads", "0"], "--threads"),
    case(["accuracy", "--presets", "nope"], "--presets", "nope"),
    case(["accuracy", "--presets", ","], "--presets"),
    case(["accuracy", "--integrator", "nope"], "--integrator", "nope"),
    # stability
    case(["stability", "--k", "0"], "--k"),
    case(["stability", "--k", "-1"], "--k"),
    case(["stability", "--k", "nan"], "--k"),
    case(["stability", "--k", "1e400"], "--k"),
    case(["stability", "--k", "1,x"], "--k"),
    case(["stability", "--k", ""], "--k"),
    case(["stability", "--presets", "nope"], "--presets", "nope"),
    case(["stability", "--integrator", "nope,rk4"], "--integrator", "nope"),
    # the one door: the integrator studies by name, their own checks, and options a study does not take
    case(["analyze", "accuracy", "--n", "1"], "--n"),
    case(["analyze", "accuracy", "--window", "nope"], "--window", "nope"),
    case(["analyze", "accuracy", "--seed", str(2**64)], "--seed"),
    case(["analyze", "accuracy", "--integrator", "nope"], "--integrator", "nope"),
    case(["analyze", "stability", "--k", "0"], "--k"),
    case(["analyze", "stability", "--presets", "nope"], "--presets", "nope"),
    case(["analyze", "accuracy", "--res", "41"], "--res", "accuracy"),
    case(["analyze", "accuracy", "--tol", "1e-6"], "--tol", "accuracy"),
    case(["analyze", "stability", "--seed", "3"], "--seed", "stability"),
    case(["analyze", "stability", "--window", "home"], "--window", "stability"),
    case(["analyze", "friction", "--integrator", "rk4"], "--integrator", "friction"),
    case(["analyze", "friction", "--n", "20"], "--n", "friction"),
    case(["analyze", "cells", "--window", "home"], "--window", "writeup"),
    case(["analyze", "all", "--quick", "--k", "5e5"], "--k", "writeup"),
    case(["analyze", "converged", "--quiet"], "--quiet", "writeup"),
    case(["analyze", "accuracy", "cells"], "accuracy", "alone"),
    case(["analyze", "cells", "friction"], "friction", "alone"),
    case(["analyze", "--report-only", "--window", "home"], "--window", "--report-only"),
    case(["analyze", "cells", "--quick", "--device", "gpu"], "--device", "gpu"),
    case(["analyze", "accuracy", "--device", "cpu"], "--device", "accuracy"),
]


@pytest.mark.parametrize("args, names", BAD)
def test_bad_option_is_one_line_exit_2_before_any_work(work, snapshot, no_work, dicetrace_cli, assert_one_line_error,
                                                       args, names):
    before = snapshot(work)
    res = dicetrace_cli(*args, "--out", OUT, cwd=work)
    assert_one_line_error(res, *names)
    assert no_work == []
    assert not (work / OUT).exists()
    assert snapshot(work) == before


@pytest.mark.parametrize("args, names", [
    case(["analyze", "cells", "--seed", "-1"], "--seed"),
    case(["analyze", "converged", "--tol", "nan"], "--tol"),
    case(["accuracy", "--n", "1000000000"], "--n"),
    case(["stability", "--k", "0"], "--k"),
])
def test_the_default_output_folder_is_not_made_either(work, snapshot, no_work, dicetrace_cli, assert_one_line_error,
                                                      args, names):
    before = snapshot(work)
    assert_one_line_error(dicetrace_cli(*args, cwd=work), *names)
    assert not (work / "dicetrace-results").exists() and snapshot(work) == before


@pytest.mark.parametrize("args, option", [
    (["analyze", "cells", "--quick", "--res", "401"], "--res"),
    (["analyze", "animation", "--quick", "--res", "101"], "--res"),  # res² × 6 frames
    (["accuracy", "--quick", "--n", "100000"], "--n"),
])
def test_a_size_that_does_not_fit_the_memory_available_is_refused(work, no_work, dicetrace_cli, assert_one_line_error,
                                                                   monkeypatch, args, option):
    """With 32 MiB available (MemAvailable, patched) a run whose estimate is larger is refused by name."""
    monkeypatch.setattr("dicetrace.memory.available_memory", lambda: 32 * 2**20)
    line = assert_one_line_error(dicetrace_cli(*args, "--out", OUT, cwd=work), option, "32 MiB available")
    assert line.startswith(f"dicetrace: error: {option} ")
    assert no_work == [] and not (work / OUT).exists()


@pytest.mark.parametrize("args, started", [
    (["analyze", "cells", "--quick", "--res", "41", "--seed", "7"], "analyze"),
    (["analyze", "converged", "--quick", "--integrator", "contact-tsit5", "--tol", "1e-6"], "analyze"),
    (["analyze", "converged", "--quick", "--integrator", "rk4"], "analyze"),
    (["analyze", "i", "--quick", "--res", "21"], "analyze"),
    (["accuracy", "--quick", "--window", "red-sea", "--n", "20", "--seed", "3", "--presets", "seed",
      "--integrator", "rk4,contact-substep"], "accuracy"),
    (["accuracy", "--quick", "--window", "0,1,3,4"], "accuracy"),
    (["stability", "--quick", "--k", "5e5,5e6", "--presets", "physical"], "stability"),
    (["analyze", "accuracy", "--quick", "--window", "red-sea", "--n", "20", "--seed", "3", "--presets", "seed",
      "--integrator", "rk4,contact-substep", "--threads", "1", "-q"], "accuracy"),
    (["analyze", "stability", "--quick", "--k", "5e5,5e6", "--presets", "physical"], "stability"),
    (["analyze", "friction", "--quick"], "friction"),
    (["analyze", "Friction", "--quick", "--quiet"], "friction"),
    (["analyze", "cells", "--quick", "--device", "cpu"], "analyze"),
    (["analyze", "cells", "--quick", "--device", "auto"], "analyze"),
])
def test_good_options_pass_the_checks(work, no_work, dicetrace_cli, args, started):
    """Valid options reach the study (the sentinel): the checks refuse only what is bad."""
    res = dicetrace_cli(*args, "--out", OUT, cwd=work)
    assert no_work == [started], res.stderr
    assert (work / OUT).is_dir()  # made once every option had passed


@pytest.mark.parametrize("command", [["analyze", "wedge", "--quick"], ["accuracy", "--quick"], ["stability", "--quick"],
                                     ["analyze", "friction", "--quick"]])
@pytest.mark.parametrize("where", ["afile", "afile/deeper"])
def test_an_output_folder_that_cannot_be_made_is_one_line(work, snapshot, no_work, dicetrace_cli, assert_one_line_error,
                                                          command, where):
    before = snapshot(work)
    assert_one_line_error(dicetrace_cli(*command, "--out", where, cwd=work), "--out", "afile")
    assert no_work == [] and snapshot(work) == before


@pytest.mark.parametrize("study", ["accuracy", "stability", "friction"])
def test_a_reduced_integrator_study_into_committed_results_is_refused(work, snapshot, no_work, dicetrace_cli,
                                                                      assert_one_line_error, study):
    """analysis/accuracy takes only full runs: a --quick one is refused by name, before any work."""
    from dicetrace.studies.outputs import COMMITTED_MARKER

    (work / "analysis" / "accuracy").mkdir(parents=True)
    (work / "analysis" / COMMITTED_MARKER).write_text("")
    before = snapshot(work)
    res = dicetrace_cli("analyze", study, "--quick", "--out", "analysis/accuracy", cwd=work)
    assert_one_line_error(res, "--out", "--quick")
    assert no_work == [] and snapshot(work) == before


def test_a_gpu_asked_for_where_there_is_none_is_one_line_before_any_work(work, snapshot, no_work, dicetrace_cli,
                                                                          assert_one_line_error):
    from dicetrace.devices import gpu_unavailable_reason

    if gpu_unavailable_reason() is None:
        pytest.skip("this machine has a GPU (or the simulator is on)")
    before = snapshot(work)
    assert_one_line_error(dicetrace_cli("analyze", "cells", "--quick", "--device", "cuda", "--out", OUT, cwd=work),
                          "--device", "cuda")
    assert no_work == [] and not (work / OUT).exists() and snapshot(work) == before


# -- a full disk while the studies write (issue 47 F2) -------------------------------------------------------------


def _half_then_enospc(write):
    """``write`` (Path.write_bytes or DataFrame.to_csv) made to write half its content, then fail as a full disk."""
    import errno
    import io

    def full(self, target, *args, **kwargs):
        if write.__name__ == "to_csv":
            buf = io.StringIO()
            write(self, buf, *args, **kwargs)
            data = buf.getvalue().encode()
        else:
            data = bytes(target)
            target = self
        with open(target, "wb") as f:
            f.write(data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")
    return full


def test_figures_tables_and_results_on_a_full_disk_keep_the_old_files_and_name_the_new(tmp_path, monkeypatch,
                                                                                     snapshot):
    """A figure, a CSV table, a results JSON and REPORT.md whose write fails half way (a full disk): the old file
    is whole under its name, no temporary is left, and the error names the file (once: a 0-byte or half figure under
    its final name, and a bare 'No space left on device')."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from dicetrace.sinks._common import OutputError
    from dicetrace.studies.context import Output, write_json
    from dicetrace.studies.report import build

    out = Output(tmp_path)
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    out.save_fig(fig, "a_line")
    out.write_csv(pd.DataFrame({"x": range(100)}), "a_table")
    write_json(out.res_dir / "cells.json", {"study": "cells", "quick": True, "n": 1})
    build(tmp_path)
    before = snapshot(tmp_path)

    with monkeypatch.context() as mp:
        mp.setattr(Path, "write_bytes", _half_then_enospc(Path.write_bytes))
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, 1])
        with pytest.raises(OutputError, match=r"cannot write figure '.*figures/a_line\.png': No space left on device"):
            out.save_fig(fig, "a_line")
    with monkeypatch.context() as mp:
        mp.setattr(pd.DataFrame, "to_csv", _half_then_enospc(pd.DataFrame.to_csv))
        with pytest.raises(OutputError, match=r"cannot write table '.*results/a_table\.csv': No space left"):
            out.write_csv(pd.DataFrame({"x": range(200)}), "a_table")
    with monkeypatch.context() as mp:
        mp.setattr(Path, "write_text", lambda self, text: _half_then_enospc(Path.write_bytes)(self, text.encode()))
        with pytest.raises(OutputError, match=r"cannot write results file '.*results/cells\.json': No space left"):
            write_json(out.res_dir / "cells.json", {"study": "cells", "quick": True, "n": 2})
        with pytest.raises(OutputError, match=r"cannot write report '.*REPORT\.md': No space left"):
            build(tmp_path)
    assert snapshot(tmp_path) == before  # every old file whole, no temporary left


@pytest.mark.slow
def test_analyze_onto_a_full_disk_is_one_line_naming_the_file_and_leaves_no_broken_file(tmp_path, tmpfs,
                                                                                       dicetrace_cli):
    """``analyze cells --quick`` into a 64 KiB file system: its grid cache is skipped with a warning, then a figure
    or a results file does not fit. One error line naming that file (exit 2); everything under OUT is whole:
    PNGs decode, JSON parses, no 0-byte file, no temporary."""
    import json

    from PIL import Image

    res = dicetrace_cli("analyze", "cells", "--quick", "--out", str(tmpfs / "OUT"), cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    errors = [line for line in res.stderr.splitlines() if line.startswith("dicetrace: error: ")]
    assert len(errors) == 1 and f"'{tmpfs / 'OUT'}/" in errors[0] and "No space left on device" in errors[0], \
        res.stderr
    files = [p for p in (tmpfs / "OUT").rglob("*") if p.is_file()]
    assert not [p for p in files if p.name.startswith(".")]  # no temporary
    for p in files:
        assert p.stat().st_size > 0, p
        if p.suffix == ".png":
            with Image.open(p) as im:
                im.load()  # the whole image decodes
        elif p.suffix == ".json":
            json.loads(p.read_text())
