"""The contact-set sequence (docs/model.md §8): recording it step by step, or from a height series.

The writeup calls it the "ground contact event sequence".

A contact set is an 8-bit mask, bit k = node k+1 at or below the ground
(absolute z ≤ 0).  The sequence starts with the empty set; after every step
from the second one on, up to and including the stopping step, the current
set is appended when it differs from the last recorded one (docs/model.md §8).
The same ``record_set`` serves the run loop, the specialised seed kernel
(``core.fast``) and ``contact_sets_from_heights`` (used on hand-built
height series in tests).
"""

from __future__ import annotations

from dicetrace.core._jit import jit


@jit(inline="always")
def contact_mask(z):
    """The contact set of the node heights ``z`` (8,): bit k set when node k+1 is at or below the ground."""
    mask = 0
    for k in range(8):
        if z[k] <= 0.0:
            mask |= 1 << k
    return mask


@jit(inline="always")
def record_set(n, mask, last_mask, sets, set_steps, nsets):
    """Append ``mask`` seen at step ``n`` if it is new.

    Returns (nsets, last_mask, ok); ok is False when the buffer is full.
    """
    if n >= 2 and mask != last_mask:
        if nsets >= sets.shape[0]:
            return nsets, last_mask, False
        sets[nsets] = mask
        set_steps[nsets] = n
        return nsets + 1, mask, True
    return nsets, last_mask, True


@jit
def contact_sets_from_heights(z_steps, sets, set_steps):
    """Contact-set sequence of a height series ``z_steps`` (nstep+1, 8).

    Row n holds the absolute node heights after n steps (row 0: initial
    state, never compared).  Returns the number of sets written (-1 if the
    buffers are too small).
    """
    if sets.shape[0] < 1:
        return -1
    sets[0] = 0
    set_steps[0] = 0
    nsets = 1
    last = 0
    for n in range(1, z_steps.shape[0]):
        nsets, last, ok = record_set(n, contact_mask(z_steps[n]), last, sets, set_steps, nsets)
        if not ok:
            return -1
    return nsets
