"""How a throw ended: the one ``Status`` enum of dicetrace, with its advice.

Bottom layer (imports nothing of the package).  The numba kernels return
these members (numba compiles ``IntEnum`` members as integer constants), the
Python API hands them to the user, and the Parquet tables store their
``label``.  Modelled on diffrax's ``RESULTS`` (each outcome of a solve with
its message).

A member compares equal to its integer code and to its label, so
``roll.status == "settled"`` and ``batch.status_code == Status.SETTLED`` both
read naturally.
"""

from __future__ import annotations

from enum import IntEnum
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is imported where it is used: ``import dicetrace`` loads none
    import numpy as np


class Status(IntEnum):
    """The end of a throw.

    ``label`` is the name stored in files and printed (``"settled"``);
    ``advice`` says what it means and what to do; ``failed`` marks the
    numerical failures (a blow-up is never an outcome).
    """

    SETTLED = 0, "the die came to rest; outcome is the face up (0: the top four nodes are no face)"
    TIME_CAP = 1, "the throw did not settle before the time cap (raise t_max_s, or it balances on an edge)"
    NON_FINITE = 2, "the state became NaN or infinite: the time step is too large for the stiffness"
    BLOW_UP = 3, "the energy grew beyond its start: a numerical blow-up (reduce dt or use another integrator)"
    #: Internal: the contact-set buffer was too small; ``simulate_batch`` re-runs the throw.
    BUFFER_FULL = 4, "internal: the contact-set buffer was too small (the throw is re-run with a larger one)"
    #: Internal: the throw's slice of steps ran out before it ended; the kernels' caller goes on with it.
    RUNNING = 5, "internal: the throw's slice of steps ran out before it ended (it goes on in the next slice)"

    def __new__(cls, code: int, advice: str):
        obj = int.__new__(cls, code)
        obj._value_ = code
        obj.advice = advice
        return obj

    @property
    def label(self) -> str:
        return self.name.lower()

    @property
    def failed(self) -> bool:
        """A numerical failure (non-finite state or energy blow-up)."""
        return self in (Status.NON_FINITE, Status.BLOW_UP)

    def __str__(self) -> str:
        return self.label

    def __format__(self, spec: str) -> str:
        return format(self.label, spec)

    def __eq__(self, other) -> bool:
        if isinstance(other, str):
            return self.label == other
        return int.__eq__(self, other)

    def __ne__(self, other) -> bool:
        return not self.__eq__(other)

    __hash__ = int.__hash__

    @classmethod
    def from_label(cls, label: str) -> "Status":
        """The member whose ``label`` is ``label`` (ValueError naming the choices)."""
        try:
            return cls[str(label).upper()]
        except KeyError:
            raise ValueError(f"unknown status {label!r} (choose from {', '.join(LABELS)})") from None

    @classmethod
    def labels_of(cls, codes) -> np.ndarray:
        """Labels (object array) of an array of integer codes."""
        import numpy as np  # here, not at the top: ``import dicetrace`` (which imports this module) loads no numpy

        return np.asarray(LABELS, dtype=object)[np.asarray(codes, dtype=np.int64)]


#: Labels of the statuses a finished throw can have, in code order (files store these).
LABELS: tuple[str, ...] = tuple(s.label for s in Status if s not in (Status.BUFFER_FULL, Status.RUNNING))
