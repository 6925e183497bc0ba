"""Arrays of initial conditions: the check that ICs are finite real numbers, and :class:`SliceICs`.

An IC is 6 numbers, ``IC_FIELDS``: the centre-of-mass velocity U (cm/s) and
the angular momentum L (node-mass·cm²/s).  :func:`validate_ic` and
:func:`validate_ics` are the one check every entry point (``simulate``,
``simulate_batch``, the seed slice) makes of ICs a caller hands in: real
numbers (not complex, boolean or text, never silently cast), finite, of the
right shape.  :class:`SliceICs` is a float64 array of ICs that also carries
their slice coordinates (what :func:`dicetrace.ics.seed_slice` returns).
"""

from __future__ import annotations

import math
import numbers

import numpy as np

IC_FIELDS = ("vx", "vy", "vz", "Lx", "Ly", "Lz")


#: What numpy dtype kinds hold, for messages about ICs that are not real numbers.
_DTYPE_KINDS = {"b": "booleans", "c": "complex numbers", "U": "text", "S": "bytes", "M": "dates", "m": "time spans", "V": "records"}


def as_real(x, what: str, shape: str) -> np.ndarray:
    """``x`` as a float64 array when it holds real numbers (integers or floats), else ValueError naming ``what``.

    Complex numbers, booleans, text, dates and other objects are refused, not cast:
    numpy's cast would drop an imaginary part with only a warning, read ``"1.5"``
    as 1.5 and ``True`` as 1.  An object array passes when every element is a
    real number (``numbers.Real``: int, float, Fraction, numpy scalars; not bool).
    """
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as e:  # e.g. rows of different lengths
        raise ValueError(f"{what} must be real numbers, {shape} ({' '.join(str(e).split())})") from None
    kind = a.dtype.kind
    if kind == "O":
        for v in a.flat:
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
                raise ValueError(f"{what} must be real numbers, {shape}: got {type(v).__name__} {_short(v)}")
    elif kind not in "iuf":
        raise ValueError(f"{what} must be real numbers, {shape}: got {_DTYPE_KINDS.get(kind, 'values')} (dtype {a.dtype})")
    try:
        return a.astype(np.float64, copy=False)
    except (OverflowError, TypeError, ValueError):  # an integer beyond float64 in an object array
        raise ValueError(f"{what} must be finite real numbers: a value is beyond float64's range") from None


def _short(v) -> str:
    r = repr(v)
    return r if len(r) <= 40 else r[:37] + "..."


def validate_ic(ic) -> np.ndarray:
    """Return ``ic`` as a float64 (6,) array or raise ValueError naming the problem."""
    a = as_real(ic, "initial condition ic", "6 of them (vx,vy,vz,Lx,Ly,Lz)")
    if a.shape != (6,):
        raise ValueError(f"initial condition must have 6 components (vx,vy,vz,Lx,Ly,Lz), got {a.size}")
    if not np.all(np.isfinite(a)):
        bad = [IC_FIELDS[i] for i in range(6) if not math.isfinite(a[i])]
        raise ValueError(f"initial condition is not finite in {', '.join(bad)}")
    return a


def validate_ics(ics) -> np.ndarray:
    """(m, 6) float64 C-contiguous array of finite ICs, or ValueError.

    A float64 C-contiguous (m, 6) input is returned as it is (no copy).
    """
    a = as_real(ics, "initial conditions ics", "an (m, 6) array")
    if a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or a.shape[1] != 6:
        raise ValueError(f"initial conditions must be an (m, 6) array, got shape {a.shape}")
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise ValueError(f"{int(bad.sum())} initial condition(s) are not finite (first: row {int(np.argmax(bad))})")
    return np.ascontiguousarray(a)


class SliceICs(np.ndarray):
    """ICs that remember where on a slice they are: what :func:`~dicetrace.ics.seed_slice` returns.

    A plain float64 array of ICs, (m, 6) or one IC (6,), with one more
    attribute: ``coords``, their slice coordinates, (m, 3) or (3,) float64
    (x, y, z; z is NaN on a 2-D slice).  :func:`~dicetrace.simulate.simulate_batch`
    passes them on to its result, so ``simulate_batch(seed_slice(xs, ys)).to_pandas()``
    has the ``x, y, z`` columns filled.

    Selecting rows (``ics[:10]``, ``ics[mask]``, ``ics[[3, 1]]``, ``ics[5]``)
    and ``ics.copy()`` keep the matching coordinates.  Anything else gives
    ICs that no longer sit at those coordinates, or need not: arithmetic and
    other ufuncs return a plain ndarray, and other views (``reshape``,
    ``ics[:, 3:]``, ...) have ``coords`` None (their rows have no
    coordinates, as for any plain array).
    """

    coords: np.ndarray | None

    def __new__(cls, ics, coords):
        obj = np.asarray(ics, dtype=np.float64).view(cls)
        c = np.asarray(coords, dtype=np.float64)
        if c.shape != obj.shape[:-1] + (3,):
            raise ValueError(f"coords of shape {c.shape} do not match ICs of shape {obj.shape}")
        obj.coords = c
        return obj

    def __array_finalize__(self, obj) -> None:
        self.coords = None  # a view or a new array: its rows need not be the coordinates' (see __getitem__)

    def __array_wrap__(self, arr, context=None, return_scalar=False):
        # ufunc results (ics * sign, ics + 1, np.sin(ics), ...) are plain arrays: no longer at those coordinates
        arr = arr.view(np.ndarray)
        return arr[()] if return_scalar else arr

    def __getitem__(self, key):
        out = super().__getitem__(key)
        if not isinstance(out, SliceICs) or self.coords is None:
            return out
        rows = self._rows(key)
        if rows is not None and out.shape[-1:] == (6,):
            try:
                c = self.coords[rows]
            except (IndexError, TypeError, ValueError):  # e.g. a mask over all 6 components: not whole rows
                return out
            if c.shape == out.shape[:-1] + (3,):
                out.coords = c
        return out

    def _rows(self, key):
        """The row part of ``key`` when it selects whole rows (all 6 components), else None."""
        if self.ndim == 1:  # one IC: only the whole of it
            whole = key is Ellipsis or (isinstance(key, slice) and key == slice(None))
            return Ellipsis if whole or (isinstance(key, tuple) and key in ((), (Ellipsis,))) else None
        if not isinstance(key, tuple):
            return key
        if len(key) == 1:
            return key[0]
        if len(key) == 2 and (key[1] is Ellipsis or (isinstance(key[1], slice) and key[1] == slice(None))):
            return key[0]
        return None

    def copy(self, order="C"):
        out = super().copy(order)
        out.coords = None if self.coords is None else self.coords.copy()
        return out

    def __reduce__(self):
        fn, args, state = super().__reduce__()
        return fn, args, (state, self.coords)

    def __setstate__(self, state):
        nd_state, coords = state
        super().__setstate__(nd_state)
        self.coords = coords



#: The columns of a throw's starting pose in the tables: its orientation as a unit quaternion (x, y, z, w; world
#: from body, scipy's and Rerun's order) and the start height of its centre of mass, cm.
POSE_FIELDS = ("qx", "qy", "qz", "qw", "z0_cm")


def validate_orientations(orientations, m: int) -> np.ndarray:
    """Per-throw orientations as world-from-body rotation matrices (m, 3, 3), or a ValueError naming the problem.

    ``orientations``: (m, 4) unit quaternions in (x, y, z, w) order, or (m, 3, 3) rotation matrices.  A
    quaternion is normalised if its norm is within 1e-6 of 1 (so a float32 copy reads back), refused
    otherwise; a matrix must be a rotation to 1e-9 (RᵀR = I, det R = +1).
    """
    a = as_real(orientations, "orientations", f"({m}, 4) quaternions x, y, z, w or ({m}, 3, 3) rotation matrices")
    if a.shape == (m, 4):
        if not np.isfinite(a).all():
            raise ValueError("orientations must be finite")
        norm = np.linalg.norm(a, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > 1e-6)
        if len(bad):
            raise ValueError(f"orientations: quaternion {int(bad[0])} has norm {norm[bad[0]]:.9g}, not 1 "
                             f"(x, y, z, w of a rotation)")
        from scipy.spatial.transform import Rotation  # scipy: only when orientations are given

        return np.ascontiguousarray(Rotation.from_quat(a / norm[:, None]).as_matrix())
    if a.shape == (m, 3, 3):
        if not np.isfinite(a).all():
            raise ValueError("orientations must be finite")
        err = np.abs(np.einsum("nji,njk->nik", a, a) - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero((err > 1e-9) | (np.linalg.det(a) < 0))
        if len(bad):
            raise ValueError(f"orientations: matrix {int(bad[0])} is not a rotation (RᵀR ≠ I or det < 0)")
        return np.ascontiguousarray(a, dtype=np.float64)
    raise ValueError(f"orientations must be ({m}, 4) quaternions x, y, z, w or ({m}, 3, 3) rotation matrices for "
                     f"{m} ICs, got shape {a.shape}")


def quaternions_xyzw(rot: np.ndarray) -> np.ndarray:
    """Unit quaternions (m, 4), x, y, z, w with w ≥ 0, of rotation matrices (m, 3, 3) (scipy's ``Rotation``)."""
    from scipy.spatial.transform import Rotation  # scipy: only when orientations are given

    return Rotation.from_matrix(np.asarray(rot, dtype=np.float64)).as_quat(canonical=True)


def validate_heights(heights_cm, m: int) -> np.ndarray:
    """Per-throw start heights of the centre of mass (m,), cm: finite numbers (one for all throws, or one each)."""
    a = as_real(heights_cm, "heights_cm", f"one number or {m}")
    if a.ndim == 0:
        a = np.full(m, float(a))
    if a.shape != (m,):
        raise ValueError(f"heights_cm must be one number or {m} numbers, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("heights_cm must be finite")
    return np.ascontiguousarray(a, dtype=np.float64)
