"""Where batches of throws run: the CPU (numba threads) or a CUDA GPU (numba-cuda), and how to choose.

``device`` is one of :data:`DEVICES`: ``"cpu"`` (the default everywhere;
:func:`use_device` changes it for a block, as ``dicetrace analyze --device``
does for every batch its studies run),
``"cuda"`` (a GPU; refused with :class:`DeviceError` where there is none) or
``"auto"`` (a GPU where numba-cuda finds one, else the CPU; one line on
standard error says which, once per process; numba-cuda's simulator,
``NUMBA_ENABLE_CUDASIM=1``, is no GPU to it).  The GPU runs the CPU's own
kernels, compiled for the device (``dicetrace.core.gpu``) with the CPU's
arithmetic (no fused multiply-adds on either): every preset's throws as on
the CPU up to the last-ulp rounding of the device's sin, cos and exp.

numba-cuda is an optional dependency (``pip install 'dicetrace[cuda]'``);
nothing here imports it unless a GPU is asked for.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import sys

#: The values of ``device``.
DEVICES = ("cpu", "cuda", "auto")


class DeviceError(ValueError):
    """A device that cannot be used (``device="cuda"`` without a GPU, or a name not in :data:`DEVICES`)."""


@functools.cache
def gpu_unavailable_reason() -> str | None:
    """None where the GPU backend can run (a CUDA GPU, or numba-cuda's simulator); else why not, in a few words."""
    try:
        from dicetrace.core import gpu  # numba-cuda: optional and heavy, imported only when a GPU is asked for
    except ImportError as exc:
        if "numba" in str(exc) or "cuda" in str(exc):
            return "numba-cuda is not installed (pip install 'dicetrace[cuda]')"
        raise
    try:
        if gpu.cuda.is_available():
            return None
    except Exception as exc:  # the CUDA driver's own failure, whatever its type: reported, never raised
        return f"numba-cuda found no usable CUDA GPU ({type(exc).__name__}: {exc})"
    return "numba-cuda found no CUDA GPU (no driver or no device)"


_DEFAULT = contextvars.ContextVar("dicetrace_device", default="cpu")


def default_device() -> str:
    """The device a batch runs on when none is given: ``"cpu"``, unless a :func:`use_device` block says otherwise."""
    return _DEFAULT.get()


@contextlib.contextmanager
def use_device(device: str):
    """Within the block, batches given no device run on ``device`` (checked now: :func:`check_device`)."""
    token = _DEFAULT.set(check_device(device))
    try:
        yield
    finally:
        _DEFAULT.reset(token)


_SAID: set = set()


def _say_once(line: str) -> None:
    """Say ``line`` on standard error, once per process; a closed or full standard error says nothing (what it
    would say never decides the run)."""
    if line not in _SAID:
        _SAID.add(line)
        try:
            sys.stderr.write(f"dicetrace: {line}\n")
        except (AttributeError, OSError, ValueError):  # None (closed at start), a full device, a closed stream
            pass


def check_device(device) -> str:
    """``device`` if it is one of :data:`DEVICES`; else a :class:`DeviceError` naming them."""
    if not isinstance(device, str) or device not in DEVICES:
        raise DeviceError(f"device must be one of {', '.join(DEVICES)}, got {device!r}")
    return device


def resolve_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"``: where ``device`` runs here.

    ``"cuda"`` without a usable GPU is a :class:`DeviceError` (one line, the
    reason); ``"auto"`` takes the GPU where there is one (never numba-cuda's
    simulator) and says which device it chose on
    standard error, once per process.
    """
    device = check_device(device)
    if device == "cpu":
        return "cpu"
    why = gpu_unavailable_reason()
    if device == "cuda":
        if why is not None:
            raise DeviceError(f"device 'cuda': {why}")
        return "cuda"
    if why is None and _simulated():
        why = "NUMBA_ENABLE_CUDASIM=1: numba-cuda's simulator is no GPU; device 'cuda' runs on it"
    if why is not None:
        _say_once(f"device auto: running on the CPU ({why})")
        return "cpu"
    _say_once(f"device auto: running on the GPU ({device_label('cuda')})")
    return "cuda"


def _simulated() -> bool:
    """Whether numba-cuda's simulator stands in for the GPU (``NUMBA_ENABLE_CUDASIM=1``): ``"cuda"`` runs on it
    (the tests of the GPU path do), ``"auto"`` never takes it for a GPU.  Asked once the GPU backend loaded."""
    from dicetrace.core import gpu

    return gpu.simulated()


def device_label(device: str) -> str:
    """What a result records as its device: ``"cpu"``, or ``"cuda: <GPU name>"``."""
    if device != "cuda":
        return "cpu"
    from dicetrace.core import gpu  # numba-cuda: optional and heavy, imported only for a GPU

    return f"cuda: {gpu.device_name()}"
