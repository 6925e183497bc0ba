"""A GPU scan on Dask: each worker on a GPU of its own, the rows of a one-GPU run.

No GPU in CI: numba-cuda's simulator (``NUMBA_ENABLE_CUDASIM=1`` with
``NUMBA_DISABLE_JIT=1``, in a subprocess) stands in for one, and three
stand-in devices for several (``core.gpu.device_count`` says 3 and
``select_device`` records its calls); the Dask workers run in that process
(``processes=False``) so that they see the stand-ins.  Under the simulator the
`seed` preset's throws are the CPU's bit for bit, so any difference between
the runs is a defect of the chunking, the device choice or the transfers.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

SIM = {"NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": "1"}

_RUN = textwrap.dedent(
    """
    import json, threading
    import dicetrace.core.gpu as gpu
    import dicetrace.simulate as simulate
    from dask.distributed import Client, LocalCluster, get_worker
    from dicetrace.ics import Grid
    from dicetrace.scan import scan

    space = Grid("seed", "home", 3)
    device_count = gpu.device_count
    gpu.device_count = lambda: 3
    selected = []
    gpu.select_device = lambda k: selected.append((k, threading.get_ident()))
    used = []  # (worker, the devices its batch ran on), batch by batch
    chunk_results = simulate.chunk_results

    def spy(bounds, run, device="cpu"):
        used.append((get_worker().address, gpu.device_ids()))
        return chunk_results(bounds, run, device)

    simulate.chunk_results = spy
    with LocalCluster(n_workers=3, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        with Client(cluster) as client:
            from dicetrace.scan.dask import gpu_places
            places = gpu_places(client)
            many = scan(space, chunk=1, device="cuda", dask=client).sort_by("ic_id")
    simulate.chunk_results = chunk_results
    gpu.device_count = device_count
    one = scan(space, chunk=1, device="cuda")  # the one (simulated) GPU, here, without Dask

    cols = ["ic_id", "outcome", "status", "steps", "t_settle_s", "contact_sequence", "n_contact_changes",
            "contact_sets", "contact_set_steps"]
    cols = [c for c in cols if c in one.column_names]
    print(json.dumps(dict(
        same=all(one.column(c).equals(many.column(c)) for c in cols), columns=cols, rows=many.num_rows,
        outcomes=sorted(set(many.column("outcome").to_pylist())),
        device=json.loads(many.schema.metadata[b"dicetrace"])["device"],
        places={a: p for a, p in places.items()}, used=used,
        selected=sorted({k for k, _ in selected}),
        threads_per_device={k: len({t for j, t in selected if j == k}) for k, _ in selected},
    )))
    """
)


@pytest.mark.slow
@pytest.mark.long
def test_dask_gpu_scan_uses_a_gpu_per_worker_and_gives_one_gpus_rows():
    """A 3×3 `seed` scan in chunks of one IC on three Dask workers and three stand-in GPUs: every worker ran its
    chunks on its own device (numbered as gpu_places numbers the workers), and the rows are those of the same
    scan on one GPU without Dask, column for column."""
    pytest.importorskip("dask.distributed")
    res = subprocess.run([sys.executable, "-c", _RUN], capture_output=True, text=True, timeout=600,
                         env={**os.environ, **SIM})
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got["rows"] == 9 and "contact_sequence" in got["columns"]
    assert got["same"], got
    assert len(got["outcomes"]) >= 2  # not a degenerate window
    assert got["device"] == "cuda: numba-cuda simulator"
    assert sorted(p for p, _n in got["places"].values()) == [0, 1, 2]
    per_worker: dict = {}
    for addr, devices in got["used"]:
        assert len(devices) == 1  # a worker's batch runs on one device only
        per_worker.setdefault(addr, set()).update(devices)
    assert all(len(d) == 1 for d in per_worker.values()), per_worker  # each worker always on the same one
    assert {a: d.pop() for a, d in per_worker.items()} == {a: got["places"][a][0] for a in per_worker}
    assert len(per_worker) >= 2  # the chunks were spread over workers (9 tasks on 3 idle workers)
    # the devices' threads: each device selected in threads of its own, at most one per stream
    assert set(got["selected"]) == {d for _a, (d,) in got["used"]}
    assert all(1 <= n <= 2 for n in got["threads_per_device"].values())


def test_gpu_places_number_workers_per_host_and_share_a_gpu_when_there_are_more():
    from dicetrace.scan.dask import _gpu_of, gpu_places

    class Client:
        def scheduler_info(self, n_workers=-1):
            return {"workers": {
                "tcp://a:3": {"host": "a", "name": 2}, "tcp://a:1": {"host": "a", "name": 0},
                "tcp://a:2": {"host": "a", "name": 1}, "tcp://b:9": {"host": "b", "name": "w-x"},
                "tcp://b:8": {"host": "b", "name": "w-y"}}}

    places = gpu_places(Client())
    assert places == {"tcp://a:1": (0, 3), "tcp://a:2": (1, 3), "tcp://a:3": (2, 3),
                      "tcp://b:9": (0, 2), "tcp://b:8": (1, 2)}
    # three workers on two GPUs: 0 and 2 share GPU 0 (half its memory each), 1 has GPU 1 to itself
    assert [_gpu_of(places[a], 2) for a in ("tcp://a:1", "tcp://a:2", "tcp://a:3")] == [(0, 0.5), (1, 1.0), (0, 0.5)]
    assert _gpu_of(places["tcp://b:8"], 4) == (1, 1.0)
    assert _gpu_of((5, 6), 1) == (0, 1 / 6)  # a dask-cuda worker sees its one GPU


def test_a_gpu_chunk_on_a_worker_without_a_gpu_is_refused_saying_why():
    """A GPU scan's chunk task on a worker that has no GPU: the device error of any GPU chunk (no device picked)."""
    from dicetrace.devices import DeviceError, gpu_unavailable_reason
    from dicetrace.ics import Grid
    from dicetrace.params import make_config
    from dicetrace.scan import ScanDefinition
    from dicetrace.scan.dask import _gpu_chunk_task

    if gpu_unavailable_reason() is None:
        pytest.skip("this machine has a GPU (or the simulator is on)")
    defn = ScanDefinition(Grid("seed", "home", 2), make_config("seed"), 4, device="cuda: Some GPU")
    with pytest.raises(DeviceError, match="device 'cuda': "):
        _gpu_chunk_task(defn.to_dict(), 0, 1, {})


def test_a_local_cluster_for_a_gpu_scan_starts_one_worker_per_gpu(monkeypatch):
    """Without --workers, a local cluster has a worker per GPU for a GPU scan (each on its own GPU), a worker per
    core for a CPU scan; --workers wins either way; cuda on a machine without a GPU is the device error."""
    import dicetrace.core.gpu as gpu
    import dicetrace.scan.dask as sd
    from dicetrace.devices import DeviceError

    monkeypatch.setattr(gpu, "device_count", lambda: 3)
    from dicetrace.devices import CPU, Device

    monkeypatch.setattr(sd, "resolve_device", lambda d: Device("cuda", "cuda: stand-in"))
    assert sd.local_worker_count(None, "cuda") == 3
    assert sd.local_worker_count(None, "cuda:0 (NVIDIA H200)") == 3
    assert sd.local_worker_count(None, "auto") == 3
    assert sd.local_worker_count(2, "cuda") == 2
    assert sd.local_worker_count(None, "cpu") == (os.cpu_count() or 1)
    monkeypatch.setattr(sd, "resolve_device", lambda d: CPU)  # auto on a machine without a GPU
    assert sd.local_worker_count(None, "auto") == (os.cpu_count() or 1)

    def no_gpu(d):
        raise DeviceError("--device cuda: no CUDA GPU")

    monkeypatch.setattr(sd, "resolve_device", no_gpu)
    with pytest.raises(DeviceError):
        sd.local_worker_count(None, "cuda")
