"""Initial conditions: validation and the seed slices of IC space.

An IC is 6 numbers: the centre-of-mass velocity U (cm/s) and the angular
momentum L (node-mass·cm²/s).  For the ``seed`` preset L is in the 2019
program's sign convention (the negative of the physical one); the
``physical`` preset takes the physical L.  Slices map 2 or 3 coordinates to
an IC with the program's arithmetic (left to right, no fused multiply-add),
so grids reproduce the program bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

IC_FIELDS = ("vx", "vy", "vz", "Lx", "Ly", "Lz")

# Seed slice (writeup section 6.2): L = x·A + y·B (+ z·C) + L0, U = x·UA + y·UB (+ z·UC).
SEED_L_DIRS = np.array([[3.2612, 3.1314, 0.0606], [2.1595, 4.5284, 3.9535], [4.5669, 3.1618, 0.4877]])
SEED_U_DIRS = np.array([[2.7083, 3.4373, 4.4365], [2.4650, 1.4853, 0.6534], [1.3925, 2.7344, 4.7875]])
SEED_L_ORIGIN = np.array([0.0, 100.0, 0.0])


def validate_ic(ic) -> np.ndarray:
    """Return ``ic`` as a float64 (6,) array or raise ValueError naming the problem."""
    try:
        a = np.asarray(ic, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"initial condition must be 6 numbers (vx,vy,vz,Lx,Ly,Lz), got {ic!r}") from None
    if a.shape != (6,):
        raise ValueError(f"initial condition must have 6 components (vx,vy,vz,Lx,Ly,Lz), got {a.size}")
    if not np.all(np.isfinite(a)):
        bad = [IC_FIELDS[i] for i in range(6) if not math.isfinite(a[i])]
        raise ValueError(f"initial condition is not finite in {', '.join(bad)}")
    return a


def validate_ics(ics) -> np.ndarray:
    """(m, 6) float64 array of finite ICs, or ValueError."""
    a = np.asarray(ics, dtype=np.float64)
    if a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or a.shape[1] != 6:
        raise ValueError(f"initial conditions must be an (m, 6) array, got shape {a.shape}")
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise ValueError(f"{int(bad.sum())} initial condition(s) are not finite (first: row {int(np.argmax(bad))})")
    return np.ascontiguousarray(a)


def seed_slice(x, y, z=None) -> np.ndarray:
    """ICs on the writeup's seed slice, bit-exact with the program.

    ``L = [x y] * A + [0 100 0]`` and ``U = [x y] * B`` (2-D); the 3-D slice
    adds ``z·C``.  Returns an (m, 6) array (U, L) for array inputs or (6,)
    for scalars.
    """
    scalar = np.ndim(x) == 0 and np.ndim(y) == 0 and (z is None or np.ndim(z) == 0)
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))[:, None]
    y = np.atleast_1d(np.asarray(y, dtype=np.float64))[:, None]
    L = x * SEED_L_DIRS[0] + y * SEED_L_DIRS[1]
    U = x * SEED_U_DIRS[0] + y * SEED_U_DIRS[1]
    if z is not None:
        z = np.atleast_1d(np.asarray(z, dtype=np.float64))[:, None]
        L = L + z * SEED_L_DIRS[2]
        U = U + z * SEED_U_DIRS[2]
    L = L + SEED_L_ORIGIN
    out = np.concatenate([U, L], axis=1)
    return out[0] if scalar else out
