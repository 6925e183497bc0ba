"""``dicetrace explore --device``: where the maps run, what the page and the API say, what is refused.

As in tests/scan/test_scan_device.py: without a GPU the refusals run in
subprocesses with ``CUDA_VISIBLE_DEVICES=""`` and numba-cuda's simulator
off; a map on the GPU runs under the simulator (``NUMBA_ENABLE_CUDASIM=1``,
``NUMBA_DISABLE_JIT=1``: slow, a 4×4 map), where the `seed` preset's throws
are the CPU's bit for bit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import threading
import urllib.request

import pytest

from explore_helpers import RES, WINDOW

NO_GPU = {"CUDA_VISIBLE_DEVICES": "", "NUMBA_ENABLE_CUDASIM": None, "NUMBA_DISABLE_JIT": None}
SIM = {"NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": "1"}


def _env(over: dict) -> dict:
    return {k: v for k, v in {**os.environ, **over}.items() if v is not None}


@pytest.mark.slow  # seconds (a subprocess or a long fit): the quick loop skips it, CI runs it
def test_cuda_without_a_gpu_is_one_line_and_serves_nothing(tmp_path):
    res = subprocess.run([sys.executable, "-m", "dicetrace.cli", "explore", "--no-browser", "--device", "cuda",
                          "--out", "scans"], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                         env=_env(NO_GPU))
    assert res.returncode == 2 and res.stdout == "", res  # no "serving" line: nothing listened
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dicetrace: error: --device: device 'cuda': "), res.stderr
    assert list(tmp_path.iterdir()) == []  # not even the --out folder


@pytest.mark.slow
@pytest.mark.long
def test_auto_without_a_gpu_serves_maps_on_the_cpu_and_says_so(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "dicetrace.cli", "explore", "--no-browser", "--device", "auto",
                             "--window", WINDOW, "--res", str(RES)], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(NO_GPU))
    try:
        line = proc.stdout.readline()
        assert "serving http://127.0.0.1:" in line and "(maps on cpu;" in line, line
        base = line.split("serving ", 1)[1].split()[0].split("/?")[0]
        with urllib.request.urlopen(f"{base}/api/view", timeout=60) as r:
            assert json.loads(r.read())["device"] == "cpu"
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    said = [x for x in err.splitlines() if "device" in x]
    assert said == [x for x in said if x.startswith("dicetrace: device auto: running on the CPU (")] and len(said) == 1


def test_the_page_and_the_api_name_the_device(client, tmp_path):
    assert client.get("/api/view").json()["device"] == "cpu"
    assert client.get("/api/health").json()["device"] == "cpu"
    assert '<span class="ax" id="device">maps on cpu;</span>' in client.get("/").text
    r = client.post("/api/save", params={"window": WINDOW, "res": 4, "name": "dev"})
    assert r.status_code == 200 and r.json()["device"] == "cpu"
    from dicetrace.scan import read_manifest

    assert read_manifest(tmp_path / "saved" / "dev")["definition"]["device"] == "cpu"


def test_a_page_names_the_device_it_is_given():
    from dicetrace.explore.page import page_html
    from dicetrace.explore.view import View

    assert '<span class="ax" id="device">maps on cuda: NVIDIA &lt;H200&gt;;</span>' in page_html(
        View(), can_save=False, device="cuda: NVIDIA <H200>")


@pytest.mark.parametrize("bad", ["gpu", 3])
def test_an_unknown_device_is_refused_before_anything_starts(bad):
    from dicetrace.devices import DeviceError
    from dicetrace.explore import Explorer
    from dicetrace.explore.compute import Worker

    before = threading.active_count()
    with pytest.raises(DeviceError, match="device must be one of cpu, cuda, auto"):
        Explorer(window=WINDOW, res=RES, device=bad)
    with pytest.raises(DeviceError):
        Worker(device=bad)
    assert threading.active_count() == before


def test_no_device_is_the_default_device():
    """``device=None`` is the default device (the CPU, unless a ``use_device`` block says otherwise), resolved once."""
    from dicetrace.devices import CPU
    from dicetrace.explore.compute import Worker

    w = Worker(device=None)
    try:
        assert w.device == "cpu" and w._device is CPU
    finally:
        w.shutdown()


@pytest.mark.slow
@pytest.mark.long
def test_a_map_on_the_simulated_gpu_is_the_cpu_map():
    """The explorer's worker on --device cuda (numba-cuda's simulator): its map of a 4×4 view is the CPU's."""
    code = textwrap.dedent(
        f"""
        import json
        from dicetrace.explore.compute import Worker
        from dicetrace.explore.server import make_view
        view = make_view("seed", "{WINDOW}", res="4")
        w = Worker(device="cuda")
        try:
            m = w.submit_map(view).result(timeout=600)
        finally:
            w.shutdown()
        print(json.dumps(dict(device=w.device, outcome=m.outcome.tolist(), steps=m.steps.tolist(),
                              status=m.status.tolist())))
        """
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=_env(SIM))
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got.pop("device") == "cuda: numba-cuda simulator"
    from dicetrace.explore.outcome_map import compute_map
    from dicetrace.explore.server import make_view

    m = compute_map(make_view("seed", WINDOW, res="4"))
    assert got == dict(outcome=m.outcome.tolist(), steps=m.steps.tolist(), status=m.status.tolist())
    assert len({o for row in got["outcome"] for o in row}) >= 2
