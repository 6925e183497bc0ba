"""Where batches of throws run: the CPU (numba threads) or a CUDA GPU (numba-cuda), and how to choose.

A device is asked for by name and resolved once, where a request enters
(the API's ``simulate_batch``, a scan, a study, the explorer, the command
line), into one :class:`Device` value that everything below takes: its
``kind`` (``"cpu"`` or ``"cuda"``) and the ``label`` a result records.
The name is one of :data:`DEVICES`: ``"cpu"`` (the default everywhere;
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
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Device:
    """A device, resolved (:func:`resolve_device`): where batches run, and what a result records of it.

    ``kind`` is ``"cpu"`` or ``"cuda"``; ``label`` is ``"cpu"`` or ``"cuda: <GPU name>"``.
    """

    kind: str
    label: str

    @property
    def gpu(self) -> bool:
        """Whether batches run on a CUDA GPU (numba-cuda, or its simulator)."""
        return self.kind == "cuda"

    def __str__(self) -> str:
        return self.label


#: The CPU, resolved (nothing to ask).
CPU = Device("cpu", "cpu")

_DEFAULT = contextvars.ContextVar("dicetrace_device", default=CPU)


def default_device() -> Device:
    """The device a batch runs on when none is given: the CPU, unless a :func:`use_device` block says otherwise."""
    return _DEFAULT.get()


@contextlib.contextmanager
def use_device(device):
    """Within the block, batches given no device run on ``device`` (a name or a :class:`Device`, resolved now)."""
    token = _DEFAULT.set(resolve_device(device))
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


def resolve_device(device=None) -> Device:
    """The :class:`Device` that ``device`` names here: a name of :data:`DEVICES`, a :class:`Device` (itself: it is
    resolved already) or None (:func:`default_device`).

    ``"cuda"`` without a usable GPU is a :class:`DeviceError` (one line, the
    reason); ``"auto"`` takes the GPU where there is one (never numba-cuda's
    simulator) and says which device it chose on standard error, once per
    process.
    """
    if device is None:
        return default_device()
    if isinstance(device, Device):
        return device
    device = check_device(device)
    if device == "cpu":
        return CPU
    why = gpu_unavailable_reason()
    if device == "cuda":
        if why is not None:
            raise DeviceError(f"device 'cuda': {why}")
        return _gpu()
    if why is None and _simulated():
        why = "NUMBA_ENABLE_CUDASIM=1: numba-cuda's simulator is no GPU; device 'cuda' runs on it"
    if why is not None:
        _say_once(f"device auto: running on the CPU ({why})")
        return CPU
    gpu = _gpu()
    _say_once(f"device auto: running on the GPU ({gpu.label})")
    return gpu


def _gpu() -> Device:
    from dicetrace.core import gpu  # numba-cuda: optional and heavy, imported only for a GPU

    return Device("cuda", f"cuda: {gpu.device_name()}")


def _simulated() -> bool:
    """Whether numba-cuda's simulator stands in for the GPU (``NUMBA_ENABLE_CUDASIM=1``): ``"cuda"`` runs on it
    (the tests of the GPU path do), ``"auto"`` never takes it for a GPU.  Asked once the GPU backend loaded."""
    from dicetrace.core import gpu

    return gpu.simulated()


def device_label(device) -> str:
    """What a result records as its device: ``"cpu"``, or ``"cuda: <GPU name>"`` (``device`` a name or a
    :class:`Device`; a name is resolved)."""
    return resolve_device(device).label
