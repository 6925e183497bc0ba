"""``dicetrace scan --device`` and ``scan(device=...)``: where a scan's throws run, what it records, what it refuses.

CI has no GPU: the refusals of ``--device cuda`` and the CPU fallback of
``--device auto`` run in subprocesses with ``CUDA_VISIBLE_DEVICES=""`` and
numba-cuda's simulator off (what a machine without a GPU sees, even where
the tests run on one).  A GPU scan runs under the simulator
(``NUMBA_ENABLE_CUDASIM=1`` with ``NUMBA_DISABLE_JIT=1``: the device kernels
and the physics as plain Python, slow: a 4×4 scan), where the `seed`
preset's throws are the CPU's bit for bit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pyarrow.parquet as pq
import pytest

from dicetrace.ics import Grid
from dicetrace.params import ConfigError, make_config
from dicetrace.scan import DeviceMismatchError, ScanDefinition, read_manifest, read_scan, scan
from dicetrace.scan.chunk_files import METADATA_KEY
from dicetrace.scan.folder import MANIFEST_KEY, check_folder

HOME = ["--slice", "seed", "--window", "home"]
NO_GPU = {"CUDA_VISIBLE_DEVICES": "", "NUMBA_ENABLE_CUDASIM": None, "NUMBA_DISABLE_JIT": None}
SIM = {"NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": "1"}
ROW_COLUMNS = ["ic_id", "outcome", "status", "steps", "t_settle_s", "contact_sequence", "n_contact_changes"]


def cli(*args: str, cwd, env: dict) -> subprocess.CompletedProcess:
    """``dicetrace ARGS`` in a fresh interpreter, with ``env`` over this one's (None: unset)."""
    full = {k: v for k, v in {**os.environ, **env}.items() if v is not None}
    return subprocess.run([sys.executable, "-m", "dicetrace.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600, env=full)


def chunk_devices(folder) -> set:
    return {json.loads(pq.read_schema(p).metadata[METADATA_KEY])["device"] for p in (folder / "rolls").glob("*.parquet")}


def one_error_line(res: subprocess.CompletedProcess) -> str:
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert res.stdout == "" and "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    return lines[0]


@pytest.mark.parametrize("extra", [[], ["--dask"]])
@pytest.mark.long
def test_cuda_without_a_gpu_is_one_line_and_writes_nothing(tmp_path, extra):
    res = cli("scan", *HOME, "--res", "3", "--out", "new/scan", "--device", "cuda", *extra, cwd=tmp_path, env=NO_GPU)
    assert one_error_line(res).startswith("dicetrace: error: --device: device 'cuda': ")
    assert list(tmp_path.iterdir()) == []  # no folder made


@pytest.mark.long
def test_auto_without_a_gpu_runs_on_the_cpu_says_so_once_and_records_cpu(tmp_path):
    res = cli("scan", *HOME, "--res", "3", "--chunk", "4", "--out", "s", "--device", "auto", "-q", cwd=tmp_path,
              env=NO_GPU)
    assert res.returncode == 0, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dicetrace: device auto: running on the CPU ("), res.stderr
    assert read_manifest(tmp_path / "s")["definition"]["device"] == "cpu"
    assert chunk_devices(tmp_path / "s") == {"cpu"}
    assert len(list((tmp_path / "s" / "rolls").glob("*.parquet"))) == 3
    # the same rows as a scan that never asked for a GPU
    want = scan(Grid("seed", "home", 3), chunk=4).to_pandas()
    got = read_scan(tmp_path / "s")
    assert got[ROW_COLUMNS].equals(want[ROW_COLUMNS])


@pytest.mark.long
def test_auto_never_takes_numba_cudas_simulator_for_a_gpu(tmp_path):
    """``NUMBA_ENABLE_CUDASIM=1`` (without NUMBA_DISABLE_JIT, whose device kernels fail): ``--device auto`` runs on
    the CPU, says why in one line, and records the CPU (once "running on the GPU (cuda: numba-cuda simulator)",
    exit 70, and a manifest of a simulator scan that refused the plain re-run)."""
    res = cli("scan", *HOME, "--res", "3", "--chunk", "4", "--out", "s", "--device", "auto", "-q", cwd=tmp_path,
              env={"NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": None})
    assert res.returncode == 0, res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert line.startswith("dicetrace: device auto: running on the CPU (") and "simulator is no GPU" in line, line
    assert read_manifest(tmp_path / "s")["definition"]["device"] == "cpu"
    assert chunk_devices(tmp_path / "s") == {"cpu"}
    res = cli("scan", *HOME, "--res", "3", "--chunk", "4", "--out", "s", "-q", cwd=tmp_path, env=NO_GPU)
    assert res.returncode == 0 and res.stderr == "", res.stderr  # the plain re-run resumes it


@pytest.mark.parametrize("error", [RuntimeError("a device kernel failed"), KeyboardInterrupt()],
                         ids=["error", "interrupt"])
def test_a_run_that_fails_before_its_first_chunk_leaves_no_manifest(tmp_path, monkeypatch, dicetrace_cli, error):
    """A run into a new folder that fails (or is interrupted) before its first chunk is written leaves no
    manifest, no rolls/ and no lock: the next run, of any definition and on any device, starts afresh.  A folder
    that held a manifest before keeps it."""
    from dicetrace.scan import runner

    def fails(*args, **kwargs):
        raise error

    monkeypatch.setattr(runner, "compute_chunk", fails)
    (tmp_path / "kept").mkdir()
    out = tmp_path / "kept" / "new" / "s"
    with pytest.raises(type(error)):
        scan(Grid("seed", "home", 3), out, chunk=4)
    assert list((tmp_path / "kept").iterdir()) == []  # the folders it made went too
    (tmp_path / "mine").mkdir()
    res = dicetrace_cli("scan", *HOME, "--res", "3", "--chunk", "4", "--out", str(tmp_path / "mine"), "-q",
                        cwd=tmp_path)
    assert res.returncode == (130 if isinstance(error, KeyboardInterrupt) else 70), res.stderr
    assert list((tmp_path / "mine").iterdir()) == []  # the folder was there before: it stays, empty
    monkeypatch.undo()
    scan(Grid("seed", "home", 3), tmp_path / "mine", chunk=4, max_chunks=1)
    monkeypatch.setattr(runner, "compute_chunk", fails)
    with pytest.raises(type(error)):
        scan(Grid("seed", "home", 3), tmp_path / "mine", chunk=4)  # a resume that fails: its folder is kept
    assert read_manifest(tmp_path / "mine")["definition"]["device"] == "cpu"
    assert sorted(p.name for p in (tmp_path / "mine" / "rolls").iterdir()) == ["part-000000.parquet"]
    monkeypatch.undo()
    assert scan(Grid("seed", "party", 3), tmp_path / "kept" / "new" / "s", chunk=4).complete  # another scan: afresh


@pytest.mark.slow
@pytest.mark.long
def test_cuda_scan_on_the_simulator_is_the_cpu_scan_and_resumes_only_on_its_device(tmp_path, dicetrace_cli):
    """A 4×4 `seed` scan with --device cuda on numba-cuda's simulator: the CPU scan's rows (outcome, steps,
    status, contact sequences and sets), its device in the definition and every chunk's metadata; resumed on
    the CPU it is refused in one line naming both devices, and so is the CPU scan resumed on the GPU."""
    res = cli("scan", *HOME, "--res", "4", "--chunk", "8", "--out", "gpu", "--device", "cuda", "-q", cwd=tmp_path,
              env=SIM)
    assert res.returncode == 0, res.stderr
    gpu = tmp_path / "gpu"
    assert read_manifest(gpu)["definition"]["device"] == "cuda: numba-cuda simulator"
    assert chunk_devices(gpu) == {"cuda: numba-cuda simulator"}
    assert dicetrace_cli("scan", *HOME, "--res", "4", "--chunk", "8", "--out", "cpu", "-q", cwd=tmp_path).returncode == 0
    got, want = read_scan(gpu), read_scan(tmp_path / "cpu")
    assert len(got) == 16 and got[ROW_COLUMNS].equals(want[ROW_COLUMNS])
    assert all(np.array_equal(a, b) for a, b in zip(got["contact_sets"], want["contact_sets"]))
    assert got["outcome"].nunique() >= 2  # not a degenerate window

    before = sorted(p.name for p in (gpu / "rolls").iterdir())
    back = dicetrace_cli("scan", *HOME, "--res", "4", "--chunk", "8", "--out", "gpu", "--device", "cpu", cwd=tmp_path)
    assert back.returncode == 2 and back.stdout == ""
    line, = back.stderr.strip().splitlines()
    assert line.startswith("dicetrace: error: --device: ")
    assert "'cuda: numba-cuda simulator'" in line and "'cpu'" in line
    assert sorted(p.name for p in (gpu / "rolls").iterdir()) == before

    other = cli("scan", *HOME, "--res", "4", "--chunk", "8", "--out", "cpu", "--device", "cuda", cwd=tmp_path, env=SIM)
    line = one_error_line(other)
    assert line.startswith("dicetrace: error: --device: ") and "'cpu'" in line and "'cuda: numba-cuda simulator'" in line


@pytest.mark.slow
@pytest.mark.long
def test_an_events_scan_on_the_simulator_is_the_cpu_events_scan(tmp_path, dicetrace_cli):
    """``scan --events --device cuda`` (the events kernel) on numba-cuda's simulator, 2×2 ICs of `physical`: the
    CPU events scan's rows, their event sets and times bit for bit."""
    args = ("scan", "--preset", "physical", *HOME, "--res", "2", "--events", "-q")
    res = cli(*args, "--out", "gpu", "--device", "cuda", cwd=tmp_path, env=SIM)
    assert res.returncode == 0, res.stderr
    assert dicetrace_cli(*args, "--out", "cpu", cwd=tmp_path).returncode == 0
    got, want = read_scan(tmp_path / "gpu"), read_scan(tmp_path / "cpu")
    assert read_manifest(tmp_path / "gpu")["definition"]["device"] == "cuda: numba-cuda simulator"
    assert len(got) == 4 and got[ROW_COLUMNS].equals(want[ROW_COLUMNS])
    for col in ("contact_sets", "contact_times_s"):
        assert all(np.array_equal(a, b) for a, b in zip(got[col], want[col])), col


def test_resuming_on_another_device_is_refused_naming_both(tmp_path):
    space, cfg = Grid("seed", "home", 3), make_config("seed")
    scan(space, tmp_path / "s", config=cfg, chunk=4, max_chunks=1)
    defn = ScanDefinition(space, cfg, 4)
    check_folder(tmp_path / "s", defn)  # the same device: resumes
    with pytest.raises(DeviceMismatchError, match=r"run on 'cpu', this run is on 'cuda: Some GPU'.*resume it on 'cpu'"):
        check_folder(tmp_path / "s", replace(defn, device="cuda: Some GPU"))
    report = scan(space, tmp_path / "s", config=cfg, chunk=4, device="cpu")
    assert (report.chunks_skipped, report.chunks_computed) == (1, 2)


def test_a_folder_of_a_dicetrace_before_devices_resumes_as_a_cpu_scan(tmp_path):
    """A manifest and chunk metadata without a device (every scan before GPUs) are the CPU's: resumed, not refused."""
    from dicetrace.scan.folder import _write_manifest, read_chunk_log

    space = Grid("seed", "home", 3)
    folder = tmp_path / "s"
    scan(space, folder, chunk=4, max_chunks=2)
    manifest = read_manifest(folder)
    del manifest["definition"]["device"]
    _write_manifest(folder, manifest, read_chunk_log(folder))
    assert "device" not in json.loads(pq.read_schema(folder / "_scan.parquet").metadata[MANIFEST_KEY])["definition"]
    report = scan(space, folder, chunk=4)
    assert (report.chunks_skipped, report.chunks_computed) == (2, 1)
    with pytest.raises(DeviceMismatchError):
        check_folder(folder, ScanDefinition(space, make_config("seed"), 4, device="cuda: Some GPU"))


def test_in_memory_scan_records_its_device():
    t = scan(Grid("seed", "home", 2), chunk=3, device="cpu")
    meta = json.loads(t.schema.metadata[METADATA_KEY])
    assert meta["device"] == "cpu" and meta["scan"]["device"] == "cpu"


@pytest.mark.parametrize("device", ["auto", "cuda", "gpu", "cuda: ", "", None, 1])
def test_a_definition_holds_a_resolved_device(device):
    with pytest.raises(ConfigError, match="device must be 'cpu' or 'cuda: <GPU name>'") as exc:
        ScanDefinition(Grid("seed", "home", 2), make_config("seed"), 4, device=device)
    assert exc.value.fields == ("device",)


def test_a_definition_round_trips_its_device_and_reads_none_as_cpu():
    d = ScanDefinition(Grid("seed", "home", 2), make_config("seed"), 4, device="cuda: NVIDIA H200")
    assert ScanDefinition.from_dict(d.to_dict()) == d
    old = {k: v for k, v in d.to_dict().items() if k != "device"}
    assert ScanDefinition.from_dict(old).device == "cpu"


def test_a_bad_device_argument_is_refused_before_any_work(tmp_path):
    from dicetrace.devices import DeviceError

    with pytest.raises(DeviceError, match="device must be one of cpu, cuda, auto, got 'gpu'"):
        scan(Grid("seed", "home", 2), tmp_path / "s", device="gpu")
    defn = ScanDefinition(Grid("seed", "home", 2), make_config("seed"), 4)
    with pytest.raises(ValueError, match="not both"):
        scan(defn, tmp_path / "s", device="cpu")
    assert list(tmp_path.iterdir()) == []


def test_a_gpu_scan_is_not_timed_on_the_cpu():
    from dicetrace.scan.estimate import estimate_scan

    defn = ScanDefinition(Grid("seed", "home", 2000), make_config("seed"), 8192, device="cuda: NVIDIA H200")
    est = estimate_scan(defn)
    assert est.seconds is None and est.device == "cuda: NVIDIA H200"
    assert "on cuda: NVIDIA H200 (time not estimated on a GPU)" in est.describe()


@pytest.mark.slow
@pytest.mark.long
def test_on_dask_a_worker_resolves_the_device(tmp_path, dicetrace_cli):
    """The chunk tasks run on the device as a worker resolves it: recorded in the definition and every chunk;
    --device cuda on a --scheduler cluster whose workers have no GPU is one line naming --device, nothing written."""
    pytest.importorskip("dask.distributed")
    from dask.distributed import Client, LocalCluster

    from dicetrace.devices import DeviceError, gpu_unavailable_reason
    from dicetrace.scan.dask import worker_device

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        with Client(cluster) as client:
            report = scan(Grid("seed", "home", 3), tmp_path / "d", chunk=4, dask=client, device="cpu")
            assert report.complete
            assert read_manifest(tmp_path / "d")["definition"]["device"] == "cpu"
            assert chunk_devices(tmp_path / "d") == {"cpu"}
            if gpu_unavailable_reason() is not None:  # the workers, started from here, see what this process sees
                with pytest.raises(DeviceError, match="device 'cuda': "):
                    worker_device(client, "cuda")
        if gpu_unavailable_reason() is not None:
            res = dicetrace_cli("scan", *HOME, "--res", "3", "--out", "new", "--scheduler", cluster.scheduler_address,
                                "--device", "cuda", cwd=tmp_path)
            assert res.returncode == 2 and res.stdout == ""
            assert res.stderr.strip().splitlines() == [res.stderr.strip()]
            assert res.stderr.startswith("dicetrace: error: --device: device 'cuda': "), res.stderr
            assert not (tmp_path / "new").exists()


@pytest.mark.slow
@pytest.mark.long
def test_a_new_gpu_scan_takes_chunks_that_fill_a_gpu_and_a_cpu_scan_the_cpus(tmp_path):
    """Without --chunk, a new scan on a GPU runs 2¹⁸ ICs a chunk (one launch each), a CPU scan 8192."""
    from dicetrace.scan import DEFAULT_CHUNK, GPU_DEFAULT_CHUNK

    assert cli("scan", *HOME, "--res", "3", "--out", "g", "--device", "cuda", "-q", cwd=tmp_path, env=SIM).returncode == 0
    assert read_manifest(tmp_path / "g")["definition"]["chunk"] == GPU_DEFAULT_CHUNK == 2**18
    assert cli("scan", *HOME, "--res", "3", "--out", "c", "-q", cwd=tmp_path, env={}).returncode == 0
    assert read_manifest(tmp_path / "c")["definition"]["chunk"] == DEFAULT_CHUNK
