"""``_jit.gpu_fence``: nothing on the CPU; on a GPU, a thread's fenced local records are read again after it.

The GPU kernels keep each thread's records in local arrays; NVVM kept every
value read from them in registers for as long as it was used again, and the
`physical` kernels spilled 1.4-1.8 kB a thread (``benchmarks/bench_ptxas.py``).
A fence (an empty inline assembly statement that clobbers memory, emitted
only when numba-cuda compiles a function) makes a device function read the
records again instead; the kernels make their local records visible to it
(``core.gpu._fenced``).  The CPU's kernels must be the same instructions with
or without it: that is what keeps them bit for bit and as fast as before.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap

import numba
import numpy as np
import pytest

from dicetrace.core._jit import gpu_fence


@numba.njit
def _fenced_sum(a, n):
    s = 0.0
    for i in range(n):
        a[i % 3] = s + 1.0
        gpu_fence()
        s += a[i % 3] * 2.0
    return s


@numba.njit
def _plain_sum(a, n):
    s = 0.0
    for i in range(n):
        a[i % 3] = s + 1.0
        s += a[i % 3] * 2.0
    return s


def _instructions(fn) -> list[str]:
    """The machine code of ``fn``'s one compiled signature, its own name taken out, comments and directives dropped."""
    lines = (line.split("#")[0].strip() for line in fn.inspect_asm(fn.signatures[0]).splitlines())
    return [re.sub(r"\w*(_fenced_sum|_plain_sum)\w*", "FN", line) for line in lines if line and not line.startswith(".")]


def test_a_fence_is_no_instruction_on_the_cpu():
    """Where a store is read back at once, a compiler barrier would force the load; the CPU code has none: the
    function with the fence compiles to the very instructions of the one without."""
    assert _fenced_sum(np.zeros(3), 5) == _plain_sum(np.zeros(3), 5) == 242.0
    fenced, plain = _instructions(_fenced_sum), _instructions(_plain_sum)
    assert len(plain) > 20
    assert fenced == plain


def test_a_fence_is_nothing_in_plain_python():
    """Under ``NUMBA_DISABLE_JIT`` (the GPU simulator's tests run the kernels so) the fence is a Python no-op."""
    code = "from dicetrace.core import _jit; assert _jit.gpu_fence is _jit._no_fence; print(_jit.gpu_fence())"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "NUMBA_DISABLE_JIT": "1"})
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip() == "None"


_PTX = textwrap.dedent(
    """
    import json, types
    import numba.cuda.dispatcher as d
    import numba.cuda.cudadrv.devices as devs
    fake = types.SimpleNamespace(compute_capability=(9, 0))
    d.get_current_device = lambda: fake
    devs.get_context = lambda *a, **k: types.SimpleNamespace(device=fake)
    import numba
    from numba import cuda, float64, int64
    from dicetrace.core import gpu
    from dicetrace.core._jit import gpu_fence

    @numba.njit
    def twice(a, i):  # a CPU function, compiled by numba-cuda as a device function, as the physics is
        x = a[i]
        gpu_fence()
        return x + a[i]

    def fenced(out, i):
        a = cuda.local.array(4, float64)
        gpu._fenced(a)
        a[i] = out[0]
        out[1] = twice(a, i)

    def unfenced(out, i):
        a = cuda.local.array(4, float64)
        a[i] = out[0]
        out[1] = twice(a, i)

    loads = {}
    for k in (fenced, unfenced):
        ptx, _ = cuda.compile_ptx(k, (float64[:], int64), cc=(9, 0))
        loads[k.__name__] = ptx.count("ld.local.f64")
    print(json.dumps(loads))
    """
)


@pytest.mark.slow
def test_on_a_gpu_fenced_local_records_are_read_again_after_a_fence():
    """Compiled for sm_90 with NVIDIA's NVVM (skipped where it is missing, as in CI): the kernel stores a[i],
    reads it, fences and reads it again.  With its local array fenced, the read after the fence is a load
    (the one before uses the value stored); an array the kernel did not fence is known to NVVM alone, and
    both reads use the stored value, with no load at all."""
    from tests.core.test_gpu import _nvvm_missing

    why = _nvvm_missing()
    if why:
        pytest.skip(why)
    res = subprocess.run([sys.executable, "-c", _PTX], capture_output=True, text=True, timeout=600)
    if res.returncode != 0 and "DynamicLibNotFoundError" in res.stderr:
        pytest.skip("NVIDIA's compiler libraries are incomplete here: " + res.stderr.strip().splitlines()[-1][:200])
    assert res.returncode == 0, res.stderr[-3000:]
    assert json.loads(res.stdout) == {"fenced": 1, "unfenced": 0}
