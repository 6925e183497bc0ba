"""dicetrace: the chaos of a rolling die, simulated, recorded and analysed.

A throw is ``dicetrace.simulate.simulate``; from here are importable
``simulate_batch`` (many throws), ``Record`` (what a throw keeps: trace channels, exact events),
``Status`` (how a throw ended), ``make_config`` and ``INTEGRATORS`` (the
integrator table).  They are loaded on first use, so ``import dicetrace``
stays cheap (no numba).
"""

__version__ = "0.1.0"

import importlib  # noqa: E402

from dicetrace.status import Status  # noqa: E402  (bottom layer, no numba)

_LAZY = {
    "simulate_batch": "dicetrace.simulate",
    "Record": "dicetrace.saving",
    "Roll": "dicetrace.simulate",
    "BatchResult": "dicetrace.simulate",
    "make_config": "dicetrace.params",
    "INTEGRATORS": "dicetrace.params",
    "Config": "dicetrace.params",
}

__all__ = ["Status", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'dicetrace' has no attribute {name!r}")
