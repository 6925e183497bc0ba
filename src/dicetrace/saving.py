"""What a simulation keeps: one request, :class:`Record`, for the per-step trace channels and the exact contact events.

``simulate(ic, record=...)`` keeps what it asks for; ``simulate_batch(ics, record=...)``
and the scans keep summaries, and with ``Record.events_only()`` the exact contact
events (docs/model.md §8.1); a batch never keeps trace channels.  The request
travels as it is from the API through the batch chunks and the scan definition to
the kernels' entry points (``core.kernels``, ``core.gpu``), which choose their
compiled loop from it: this module is in the bottom layer (numpy only), so that
``core`` may import it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

#: The per-step trace channels of a :class:`Record`, in the order its fields list them.
TRACE_CHANNELS = ("states", "energy", "forces")


@dataclass(frozen=True)
class Record:
    """What a simulation computes and keeps besides its summary: per-step channels and exact contact events.

    Parameters
    ----------
    states
        Node positions, centre of mass (position, velocity), orientation
        quaternion and angular momentum, every step.
    energy
        Energies every step (stop-test, translational and rotational kinetic,
        gravitational, elastic, total), node-mass·cm²/s².
    forces
        Contact force on every node, every step.
    events
        The exact contact events (contact integrators only; docs/model.md
        §8.1): the contact sets inside the scheme's sub-steps, located where
        nodes enter or leave the ground, with their times, instead of the
        sets at output-step ends.  The throw is the same, bit for bit.

    The first three are the trace channels, which only :func:`~dicetrace.simulate.simulate`
    keeps; a batch or a scan keeps events alone (:meth:`events_only`).
    """

    states: bool = True
    energy: bool = True
    forces: bool = False
    events: bool = False

    def __post_init__(self) -> None:
        for name in (*TRACE_CHANNELS, "events"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise TypeError(f"Record({name}=...) must be True or False, got {v!r}")
            object.__setattr__(self, name, bool(v))
        if not (self.traces or self.events):
            raise ValueError("Record() asks for nothing: request states, energy, forces or events, or pass record=None")

    @classmethod
    def events_only(cls) -> Record:
        """The exact contact events and no trace channel: what a batch or a scan can keep."""
        return cls(states=False, energy=False, forces=False, events=True)

    @property
    def channels(self) -> tuple[str, ...]:
        """The trace channels asked for, by name (``TRACE_CHANNELS`` order)."""
        return tuple(name for name in TRACE_CHANNELS if getattr(self, name))

    @property
    def traces(self) -> bool:
        """Whether any per-step trace channel is asked for."""
        return bool(self.channels)


def check_record(record) -> Record | None:
    """``record`` as given where it is a :class:`Record` or None; a TypeError naming it otherwise."""
    if record is not None and not isinstance(record, Record):
        raise TypeError(f"record must be a dicetrace.Record or None, not {type(record).__name__}")
    return record


def wants_events(record: Record | None) -> bool:
    """Whether ``record`` asks for the exact contact events (None asks for nothing)."""
    return record is not None and record.events


def summary_record(record, what: str = "simulate_batch") -> Record | None:
    """``record`` checked for a run that keeps summaries only (a batch, a scan): None or events alone.

    A request for trace channels is refused with one ValueError naming
    ``what`` and the channels (a batch keeps no per-step trace).
    """
    record = check_record(record)
    if record is not None and record.traces:
        raise ValueError(
            f"{what} keeps no per-step channels, and record asks for {', '.join(record.channels)}: pass "
            "record=Record.events_only() for the exact contact events, or record=None (simulate() traces one throw)"
        )
    return record


#: The default of the deprecated keyword ``events=`` (:func:`record_with_events`): not given.
NOT_GIVEN = object()


def record_with_events(record, events, where: str, stacklevel: int = 3) -> Record | None:
    """The deprecated keyword ``events=`` of ``where`` (``simulate``, ``simulate_batch``, ``scan``) folded into the
    request ``record``: ``events=True`` is ``record`` with events (``Record.events_only()`` where ``record`` is
    None), ``events=False`` leaves it as it is.  Given at all (anything but :data:`NOT_GIVEN`), it warns
    (DeprecationWarning, naming the replacement, at the caller of ``where``: ``stacklevel`` as ``warnings.warn``
    counts it from here)."""
    record = check_record(record)
    if events is NOT_GIVEN:
        return record
    warnings.warn(
        f"{where}(events=...) is deprecated and goes in the next release: pass record=Record.events_only(), or "
        "Record(..., events=True) beside trace channels (dicetrace.Record)", DeprecationWarning, stacklevel=stacklevel)
    if not isinstance(events, (bool, np.bool_)):
        raise ValueError(f"events must be True or False, not {events!r}")
    if not events:
        return record
    return Record.events_only() if record is None else replace(record, events=True)

