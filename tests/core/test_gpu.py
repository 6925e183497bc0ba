"""The GPU backend (``dicetrace.core.gpu``) against the CPU's kernels, without a GPU and, where one is lent, on it.

Without a GPU the kernels run under numba-cuda's simulator
(``NUMBA_ENABLE_CUDASIM=1``) in a subprocess that also sets
``NUMBA_DISABLE_JIT=1``: the kernel *and every physics function it calls*
then run as plain Python with the host's math library, one thread per throw
as on the device, through the same chunking, buffer retries and transfers.
Plain Python rounds every operation as the CPU's build does (strict IEEE
arithmetic, no fused multiply-adds, for every scheme), so every path must
match the compiled CPU bit for bit, and any difference is a defect of the
device path.

``test_kernels_compile_for_the_device`` compiles both kernels to PTX with
NVIDIA's NVVM (no GPU needed; skipped where the NVVM library is missing, as
in CI) and checks that both are compiled without contraction.
Tests marked ``gpu`` run on a real device and are skipped without one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dicetrace.devices import DeviceError, resolve_device
from dicetrace.ics import seed_slice
from dicetrace.simulate import simulate_batch

#: Runs ``simulate_batch`` in a fresh interpreter and prints its summaries as JSON.
_RUN = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    from dicetrace.ics import seed_slice
    from dicetrace.simulate import simulate_batch
    a = json.loads(sys.argv[1])
    ics = seed_slice(np.array(a["xs"]), np.array(a["ys"]))
    r = simulate_batch(ics, config=a["preset"], device=a["device"], cap=a["cap"], **a["options"])
    print(json.dumps(dict(device=r.device, outcome=r.outcome.tolist(), steps=r.steps.tolist(),
                          status=r.status_code.tolist(), offsets=r.set_offsets.tolist(), sets=r.sets.tolist(),
                          set_steps=r.set_steps.tolist(),
                          set_times=None if r.set_times is None else r.set_times.tolist())))
    """
)


def _summaries(r) -> dict:
    return dict(outcome=r.outcome.tolist(), steps=r.steps.tolist(), status=r.status_code.tolist(),
                offsets=r.set_offsets.tolist(), sets=r.sets.tolist(), set_steps=r.set_steps.tolist(),
                set_times=None if r.set_times is None else r.set_times.tolist())  # JSON keeps a float64 exactly


def _run(device: str, preset: str, xs, ys, *, cap: int = 128, env: dict | None = None, **options):
    arg = json.dumps(dict(xs=list(map(float, xs)), ys=list(map(float, ys)), preset=preset, device=device, cap=cap,
                          options=options))
    res = subprocess.run([sys.executable, "-c", _RUN, arg], capture_output=True, text=True, timeout=600,
                         env={**os.environ, **(env or {})})
    return res


SIM = {"NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": "1"}
RNG = np.random.default_rng(33)
XS, YS = RNG.uniform(0.0, 20.0, 8), RNG.uniform(0.0, 20.0, 8)


def _cpu(preset, xs, ys, **options):
    return _summaries(simulate_batch(seed_slice(xs, ys), config=preset, **options))


@pytest.mark.slow
@pytest.mark.parametrize("cap", [128, 3])
def test_seed_kernel_on_the_simulator_is_the_cpu_bit_for_bit(cap):
    """8 `seed` throws through the seed kernel (per-thread local arrays) give the CPU's status, steps,
    outcome and whole contact-set sequence; with 3 sets per throw every throw fills its buffer first and
    is re-run with more on the device, as on the CPU."""
    res = _run("cuda", "seed", XS, YS, cap=cap, env=SIM)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got.pop("device") == "cuda: numba-cuda simulator"
    want = _cpu("seed", XS, YS, cap=cap)
    assert got == want
    assert set(got["status"]) == {0} and len(set(got["outcome"])) >= 3  # settled, several faces: not a degenerate case
    if cap == 3:
        assert min(np.diff(got["offsets"])) > cap  # every throw overflowed its first buffer


@pytest.mark.slow
def test_general_kernel_strict_scheme_on_the_simulator_is_the_cpu_bit_for_bit():
    """The general kernel (a scheme's summary loop in a per-thread state record in device memory) on a
    strictly compiled scheme: `seed` with velocity Verlet gives the CPU's summaries bit for bit; in two chunks
    on one stream, so that the second chunk's throws start from the state records the first left (scratch
    that every throw sets before it reads, uploaded once)."""
    res = _run("cuda", "seed", XS[:4], YS[:4], env={**SIM, "DICETRACE_GPU_STREAMS": "1"}, integrator="verlet",
               dt_s=2e-4, chunk=2)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    got.pop("device")
    assert got == _cpu("seed", XS[:4], YS[:4], integrator="verlet", dt_s=2e-4)


@pytest.mark.slow
def test_physical_default_on_the_simulator_agrees_with_the_cpu():
    """`physical` (contact-tsit5, dense output, error control) through the general kernel: the CPU's status,
    steps, outcome and contact-set sequence on 3 throws, bit for bit (both strict: a fused multiply-add on one
    side moves the steps of about half of all throws)."""
    res = _run("cuda", "physical", XS[:3], YS[:3], env=SIM)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    got.pop("device")
    want = _cpu("physical", XS[:3], YS[:3])
    assert got == want
    assert set(want["status"]) == {0}


@pytest.mark.slow
def test_events_kernel_on_the_simulator_is_the_cpu_bit_for_bit():
    """Exact contact events on the device (the events kernel: ``scheme.roll_events`` per thread, the events'
    root scratch in the state record, the times packed beside the sets): `physical`'s 3 throws give the CPU's
    summaries, event sets, steps and times bit for bit, with 16 sets a throw, so that every throw fills its
    buffer first and is re-run with more on the device, times included."""
    res = _run("cuda", "physical", XS[:3], YS[:3], cap=16, env=SIM, events=True)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got.pop("device") == "cuda: numba-cuda simulator"
    want = _cpu("physical", XS[:3], YS[:3], events=True)
    assert got == want
    assert min(np.diff(want["offsets"])) > 16 and len(want["set_times"]) == len(want["sets"])
    plain = _cpu("physical", XS[:3], YS[:3])
    assert (want["steps"], want["outcome"]) == (plain["steps"], plain["outcome"])  # the same throws


@pytest.mark.slow
@pytest.mark.parametrize("preset,events", [("seed", False), ("physical", False), ("physical", True)])
@pytest.mark.long
def test_throws_that_outlive_a_slice_go_on_in_the_held_kernel(preset, events):
    """With slices of 60 steps every throw outlives its first launch (the seed kernel's and the local-record
    kernels' records are lost then): the throws start again in the held kernel, their records in device memory,
    and go on launch after launch; the results are the CPU's bit for bit, sets (and events' times) packed in
    throw order beside the throws that ended in the first launch (here: none)."""
    code = _RUN.replace("r = simulate_batch(",
                        "import dicetrace.core.kernels as K; K.SLICE_STEPS, K.SUMMARY_SLICES = 60, 1\nr = simulate_batch(")
    arg = json.dumps(dict(xs=list(map(float, XS[:3])), ys=list(map(float, YS[:3])), preset=preset, device="cuda",
                          cap=128, options={"events": events}))
    res = subprocess.run([sys.executable, "-c", code, arg], capture_output=True, text=True, timeout=900,
                         env={**os.environ, **SIM})
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    got.pop("device")
    want = _cpu(preset, XS[:3], YS[:3], events=events)
    assert min(want["steps"]) > 60
    assert got == want


@pytest.mark.slow  # about a second
def test_auto_without_a_gpu_runs_on_the_cpu_and_says_so_once():
    res = _run("auto", "seed", XS[:2], YS[:2], env={"NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""})
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got.pop("device") == "cpu"
    assert got == _cpu("seed", XS[:2], YS[:2])
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dicetrace: device auto: running on the CPU ("), res.stderr


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_cuda_without_a_gpu_is_one_error_line_and_runs_nothing():
    res = _run("cuda", "seed", XS[:2], YS[:2], env={"NUMBA_ENABLE_CUDASIM": "0", "CUDA_VISIBLE_DEVICES": ""})
    assert res.returncode != 0 and res.stdout == ""
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("dicetrace.devices.DeviceError: device 'cuda': "), res.stderr


@pytest.mark.parametrize("bad", ["gpu", "CUDA", "", 1])
def test_unknown_device_is_refused_naming_the_choices(bad):
    with pytest.raises(DeviceError, match="device must be one of cpu, cuda, auto"):
        simulate_batch(seed_slice([1.0], [1.0]), config="seed", device=bad)
    with pytest.raises(DeviceError):
        resolve_device(bad)


def test_cpu_result_records_its_device_in_the_table_metadata():
    r = simulate_batch(seed_slice([1.0, 2.0], [3.0, 4.0]), config="seed")
    assert r.device == "cpu"
    meta = json.loads(r.to_arrow().schema.metadata[b"dicetrace"])
    assert meta["device"] == "cpu"


def _nvvm_missing() -> str | None:
    try:
        from numba.cuda.cudadrv import nvvm

        nvvm.NVVM()
    except Exception as exc:  # no numba-cuda, or no NVVM library: the check cannot run here
        return f"NVVM unavailable ({type(exc).__name__})"
    return None


@pytest.mark.slow
@pytest.mark.long
def test_kernels_compile_for_the_device():
    """The seed, general and events kernels (and the one that packs the contact sets, steps and events' times)
    compile to PTX for an H200 (sm_90) with NVIDIA's compiler, without contraction: their only fused multiply-adds are libdevice's own (sin, cos, exp), so far fewer
    than NVVM's default makes of the same kernel."""
    why = _nvvm_missing()
    if why:
        pytest.skip(why)
    code = textwrap.dedent(
        """
        import contextlib, json, types
        import numba.cuda.dispatcher as d
        import numba.cuda.cudadrv.devices as devs
        fake = types.SimpleNamespace(compute_capability=(9, 0))
        d.get_current_device = lambda: fake  # the compute capability is all it asks the device for
        devs.get_context = lambda *a, **k: types.SimpleNamespace(device=fake)
        import numpy as np
        from numba import cuda, typeof
        from numba.cuda.cudadrv import nvvm
        from dicetrace.core import _compat
        from dicetrace.core import gpu
        from dicetrace.core.kernels import SLICE_STEPS, kernels_for
        from dicetrace.core.state import MOTION, new_work
        from dicetrace.params import make_config
        out = {}
        for name, preset, events in (("seed", "seed", False), ("physical", "physical", False),
                                     ("physical events", "physical", True)):
            kin = make_config(preset).kernel_inputs(np.zeros((2, 6)))
            seed = not events and gpu.uses_seed_kernel(kin.params, kin.off0, kin.integrator_id)
            kernel = gpu._kernel(kin.integrator_id, seed, events)
            o = [np.zeros(2, np.int8), np.zeros(2, np.int64), np.zeros(2, np.int8), np.zeros(2, np.int64),
                 np.zeros(16, np.uint8), np.zeros(16, np.int32)]
            args = (kin.ics, kin.off0, kin.params, 8, *o, SLICE_STEPS) if seed else (
                kin.ics, kin.off0, kin.params, 8, np.zeros(0, MOTION),
                new_work(kernels_for(kin.integrator_id).scheme.WORK, 0), *o, np.zeros(16 if events else 0),
                np.zeros((0, 33)), np.zeros((0, 24)), np.zeros((0, 6)), False, SLICE_STEPS, 0)
            sig = tuple(typeof(a) for a in args)
            counts = []
            for s in (True, False):
                with _compat.nvvm_without_fma(nvvm) if s else contextlib.nullcontext():
                    ptx, _ = cuda.compile_ptx(kernel.py_func, sig, cc=(9, 0))
                counts.append(ptx.count("fma.rn.f64"))
            out[name] = dict(seed_kernel=seed, fma=counts)
        entries = []
        for dt in (np.uint8, np.int32, np.float64):  # the sets, their steps, the events' times
            gather = tuple(typeof(a) for a in (np.zeros(16, dt), 8, np.zeros(3, np.int64), np.zeros(4, dt)))
            ptx, _ = cuda.compile_ptx(gpu._GATHER.py_func, gather, cc=(9, 0))
            entries.append(".entry" in ptx)
        out["gather"] = all(entries)
        print(json.dumps(out))
        """
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    if res.returncode != 0 and "DynamicLibNotFoundError" in res.stderr:  # NVVM without NVRTC (numba-cuda alone)
        pytest.skip("NVIDIA's compiler libraries are incomplete here: " + res.stderr.strip().splitlines()[-1][:200])
    assert res.returncode == 0, res.stderr[-3000:]
    out = json.loads(res.stdout)
    assert out["seed"]["seed_kernel"] and not out["physical"]["seed_kernel"]
    for name in ("seed", "physical", "physical events"):
        strict_fma, default_fma = out[name]["fma"]
        assert strict_fma < default_fma / 3, out
    assert out["gather"]  # the kernel that packs the used sets, steps and times for the copy back


def _gpu_missing() -> str | None:
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0"):
        return "the simulator is on"
    from dicetrace.devices import gpu_unavailable_reason

    return gpu_unavailable_reason()


@pytest.mark.gpu
@pytest.mark.parametrize("preset", ["seed", "physical"])
def test_real_gpu_agrees_with_the_cpu(preset):
    """On a real GPU, 2000 throws: `seed` outcomes equal to the CPU's on at least 99.9 % (the device's sin and
    cos differ in the last ulp), `physical` on at least 99 % (the same last-ulp differences, at every free-flight
    rotation of a throw several times longer, amplified by the chaos near borders); no throw fails on the device that settles on the CPU."""
    why = _gpu_missing()
    if why:
        pytest.skip(why)
    rng = np.random.default_rng(7)
    ics = seed_slice(rng.uniform(0, 20, 2000), rng.uniform(0, 20, 2000))
    a = simulate_batch(ics, config=preset)
    b = simulate_batch(ics, config=preset, device="cuda")
    assert b.device.startswith("cuda: ")
    same = np.mean(a.outcome == b.outcome)
    assert same >= (0.999 if preset == "seed" else 0.99), same
    assert not np.any((a.status_code == 0) & (b.status_code != 0))


@pytest.mark.gpu
def test_real_gpu_streams_and_pieces_give_one_streams_results(monkeypatch):
    """On a real GPU, 20,000 `seed` throws cut into pieces of 2,000 on two streams (copies and kernels overlapping)
    and with 64 contact sets a throw (some fill them and are re-run): the results of one stream running the
    whole batch as one piece, bit for bit."""
    why = _gpu_missing()
    if why:
        pytest.skip(why)
    import dicetrace.batch_chunks as bc

    rng = np.random.default_rng(11)
    ics = seed_slice(rng.uniform(0, 20, 20_000), rng.uniform(0, 20, 20_000))
    monkeypatch.setenv("DICETRACE_GPU_STREAMS", "1")
    one = simulate_batch(ics, config="seed", device="cuda", cap=64)
    monkeypatch.setenv("DICETRACE_GPU_STREAMS", "2")
    monkeypatch.setattr(bc, "GPU_PIECE_MIN", 2000)
    two = simulate_batch(ics, config="seed", device="cuda", cap=64, chunk=5000)
    assert np.any(np.diff(one.set_offsets) > 64)
    for k in ("outcome", "steps", "status_code", "set_offsets", "sets", "set_steps"):
        assert np.array_equal(getattr(one, k), getattr(two, k)), k


@pytest.mark.gpu
def test_real_gpu_events_agree_with_the_cpu():
    """On a real GPU, 1000 `physical` throws with exact contact events: outcomes equal to the CPU's on at least
    99 % (as without events), every throw's event times increasing from 0 (as on the CPU, where all 1000 are), and
    where a throw's event sets are the CPU's (most throws: the device differs only in the last ulp of sin, cos and
    exp) its times within one step (1 ms) of the CPU's: the same events, not merely the same sets."""
    why = _gpu_missing()
    if why:
        pytest.skip(why)
    rng = np.random.default_rng(8)
    ics = seed_slice(rng.uniform(0, 20, 1000), rng.uniform(0, 20, 1000))
    a = simulate_batch(ics, config="physical", events=True)
    b = simulate_batch(ics, config="physical", device="cuda", events=True)
    assert b.device.startswith("cuda: ") and b.set_times is not None
    assert np.mean(a.outcome == b.outcome) >= 0.99
    same = 0
    for i in range(len(ics)):
        ta, tb = (r.set_times[r.set_offsets[i] : r.set_offsets[i + 1]] for r in (a, b))
        sa, sb = (r.sets[r.set_offsets[i] : r.set_offsets[i + 1]] for r in (a, b))
        assert tb[0] == 0.0 and np.all(np.diff(tb) > 0)
        if len(sa) == len(sb) and np.array_equal(sa, sb):
            same += 1
            np.testing.assert_allclose(tb, ta, rtol=0, atol=1e-3)
    assert same >= 500


@pytest.mark.slow
@pytest.mark.parametrize("streams", ["1", "2"])
def test_several_gpus_share_the_chunks_and_give_one_gpus_results(streams):
    """With several GPUs the chunks are cut into pieces that go round-robin to the GPUs, each GPU's to its own
    threads (one CUDA stream each, ``DICETRACE_GPU_STREAMS``): here three stand-in devices (the simulator has
    one) on 8 `seed` throws in chunks of 4 cut in two, with 30 contact sets a throw (5 of the 8 fill them and
    are re-run on the device with more): the CPU's summaries bit for bit, in order."""
    code = textwrap.dedent(
        """
        import json, threading
        import numpy as np
        import dicetrace.batch_chunks as bc
        import dicetrace.core.gpu as gpu
        from dicetrace.ics import seed_slice
        from dicetrace.simulate import simulate_batch
        chosen, pieces = [], []
        gpu.device_count = lambda: 3
        gpu.select_device = lambda k: chosen.append((k, threading.get_ident()))
        bc.GPU_PIECE_MIN = 2
        run_batch_cuda = gpu.run_batch_cuda
        def spy(ics, *args):
            pieces.append((len(ics), args[3]))  # (off0, kp, integ, cap, events)
            return run_batch_cuda(ics, *args)
        gpu.run_batch_cuda = spy
        a = json.loads(__import__("sys").argv[1])
        r = simulate_batch(seed_slice(np.array(a["xs"]), np.array(a["ys"])), config="seed", device="cuda", chunk=4,
                           cap=30)
        print(json.dumps(dict(outcome=r.outcome.tolist(), steps=r.steps.tolist(), status=r.status_code.tolist(),
                              offsets=r.set_offsets.tolist(), sets=r.sets.tolist(), set_steps=r.set_steps.tolist(),
                              set_times=r.set_times, devices=sorted({k for k, _ in chosen}), pieces=pieces,
                              threads={k: len({t for j, t in chosen if j == k}) for k, _ in chosen})))
        """
    )
    arg = json.dumps(dict(xs=list(map(float, XS)), ys=list(map(float, YS))))
    res = subprocess.run([sys.executable, "-c", code, arg], capture_output=True, text=True, timeout=600,
                         env={**os.environ, **SIM, "DICETRACE_GPU_STREAMS": streams})
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got.pop("devices") == [0, 1, 2]  # 4 pieces round-robin: every device has one
    assert all(1 <= n <= int(streams) for n in got.pop("threads").values())  # its threads: at most one per stream
    pieces = got.pop("pieces")
    assert [m for m, cap in pieces if cap == 30] == [2, 2, 2, 2], pieces  # 2 chunks of 4, each cut in two
    assert {cap for m, cap in pieces} == {30, 240}  # and the re-runs of the throws that filled their 30 sets
    want = _cpu("seed", XS, YS, cap=30)
    assert got == want
    assert 0 < sum(np.diff(want["offsets"]) > 30) < 8  # some throws overflowed their first buffer, not all


def test_gpu_streams_setting_is_checked(monkeypatch):
    """``DICETRACE_GPU_STREAMS``: a whole number >= 1, or refused naming it (checked where numba-cuda is)."""
    pytest.importorskip("numba.cuda")
    from dicetrace.core import gpu

    monkeypatch.setenv("DICETRACE_GPU_STREAMS", "1")
    assert gpu.streams_per_device() == 1
    monkeypatch.delenv("DICETRACE_GPU_STREAMS")
    assert gpu.streams_per_device() == gpu.DEFAULT_STREAMS == 2
    for bad in ("0", "two", "-1", "1.5"):
        monkeypatch.setenv("DICETRACE_GPU_STREAMS", bad)
        with pytest.raises(ValueError, match="DICETRACE_GPU_STREAMS must be a whole number >= 1"):
            gpu.streams_per_device()


def test_pieces_cut_a_chunk_for_the_gpus_and_join_back():
    """A GPU chunk is cut into near-equal pieces of at least ``GPU_PIECE_MIN`` ICs, and its summaries joined back."""
    from dicetrace.batch_chunks import GPU_PIECE_MIN, _joined, _pieces

    assert _pieces(0, 10, 4) == [(0, 10)]  # too small to cut
    assert _pieces(5, 5 + 4 * GPU_PIECE_MIN + 3, 4) == [(5, 5 + GPU_PIECE_MIN), (5 + GPU_PIECE_MIN, 5 + 2 * GPU_PIECE_MIN + 1),
                                                       (5 + 2 * GPU_PIECE_MIN + 1, 5 + 3 * GPU_PIECE_MIN + 2),
                                                       (5 + 3 * GPU_PIECE_MIN + 2, 5 + 4 * GPU_PIECE_MIN + 3)]
    assert len(_pieces(0, 3 * GPU_PIECE_MIN - 1, 8)) == 2
    a = (np.array([1, 2], np.int8), np.array([3, 4]), np.array([5, 6], np.int8), np.array([1, 2]),
         np.array([7, 8, 9], np.uint8), np.array([1, 2, 3], np.int32))
    b = (np.array([0], np.int8), np.array([9]), np.array([1], np.int8), np.array([1]), np.array([4], np.uint8),
         np.array([5], np.int32))
    j = _joined([a, b])
    assert [x.tolist() for x in j] == [[1, 2, 0], [3, 4, 9], [5, 6, 1], [1, 2, 1], [7, 8, 9, 4], [1, 2, 3, 5]]
    assert [x.dtype for x in j] == [x.dtype for x in a]
