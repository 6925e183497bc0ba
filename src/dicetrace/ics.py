"""Initial conditions: slices of IC space, grids and samples.

An IC is 6 numbers: the centre-of-mass velocity U (cm/s) and the angular
momentum L (node-mass·cm²/s), in that order (``IC_FIELDS``).  For the
``seed`` preset L is in the 2019 program's sign convention (the negative of
the physical one); the ``physical`` preset takes the physical L.  Slices map
1–3 coordinates to an IC with the program's arithmetic (left to right, no
fused multiply-add), so grids reproduce the program bit for bit.  The check
of ICs handed in and :class:`SliceICs` live in :mod:`dicetrace.ic_arrays`,
windows and the grid point formula in :mod:`dicetrace.windows`; both are
re-exported here.

IC spaces (docs/model.md §11), all plain frozen dataclasses that turn
into JSON-able dicts and back (``to_dict`` / :func:`space_from_dict`):

:class:`Slice`
    An origin and 1–3 directions in the 6-D space: ``IC = c1·d1 + c2·d2
    (+ c3·d3) + origin``.  ``SLICES`` holds the writeup's 2-D and 3-D seed
    slices (``seed``, ``seed3``) and their Gram–Schmidt orthonormal versions
    (``seed-ortho``, ``seed3-ortho``; the writeup's "future work" 6.2).
:class:`Grid`
    A window of a slice at a resolution, with the program's point formula
    ``x = x0 + (p−1)/(n−1)·(x1−x0)``, p = 1..n (here 0-based: i = p−1).
    ``WINDOWS`` names the writeup's windows (home, zoom-out, ..., green
    island); any sub-window at any resolution is a zoom.
:class:`Sample`
    ``n`` random (uniform) or quasi-random (scrambled Sobol) points in a box
    of a slice.
:class:`Points`
    Explicit slice coordinates (e.g. the writeup's named throws).

Every space is enumerated by a linear ``ic_id`` 0..size−1 and produces any
range of it on demand (:meth:`Grid.block`), so a scan never holds more than
one chunk of ICs.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

# IC_FIELDS, validate_ic(s) and WINDOWS are re-exported: users and the README import them from here.
from dicetrace.ic_arrays import IC_FIELDS, SliceICs, as_real, validate_ic, validate_ics  # noqa: F401
from dicetrace.params import L_CONVENTIONS, ConfigError
from dicetrace.params import _show
from dicetrace.windows import WINDOWS, _is_count, get_res, get_window, grid_axis  # noqa: F401

# Seed slice (writeup section 6.2): L = x·A + y·B (+ z·C) + L0, U = x·UA + y·UB (+ z·UC).
SEED_L_DIRS = np.array([[3.2612, 3.1314, 0.0606], [2.1595, 4.5284, 3.9535], [4.5669, 3.1618, 0.4877]])
SEED_U_DIRS = np.array([[2.7083, 3.4373, 4.4365], [2.4650, 1.4853, 0.6534], [1.3925, 2.7344, 4.7875]])
SEED_L_ORIGIN = np.array([0.0, 100.0, 0.0])


def seed_slice(x, y, z=None) -> SliceICs:
    """ICs on the writeup's seed slice, bit-exact with the program.

    ``L = [x y] * A + [0 100 0]`` and ``U = [x y] * B`` (2-D); the 3-D slice
    adds ``z·C``.  Returns an (m, 6) array (U, L) for array inputs or (6,)
    for scalars: a :class:`SliceICs`, a float64 ndarray that also carries the
    slice coordinates (``.coords``, (m, 3) or (3,), z NaN on the 2-D slice), so
    ``simulate_batch(seed_slice(xs, ys))`` knows them (its table's ``x, y, z``).
    """
    scalar = np.ndim(x) == 0 and np.ndim(y) == 0 and (z is None or np.ndim(z) == 0)
    xc = as_real(x, "seed_slice x", "a number or an array")
    yc = as_real(y, "seed_slice y", "a number or an array")
    x = np.atleast_1d(xc)[:, None]
    y = np.atleast_1d(yc)[:, None]
    L = x * SEED_L_DIRS[0] + y * SEED_L_DIRS[1]
    U = x * SEED_U_DIRS[0] + y * SEED_U_DIRS[1]
    if z is not None:
        z = np.atleast_1d(as_real(z, "seed_slice z", "a number or an array"))[:, None]
        L = L + z * SEED_L_DIRS[2]
        U = U + z * SEED_U_DIRS[2]
    L = L + SEED_L_ORIGIN
    out = np.concatenate([U, L], axis=1)
    m = len(out)
    coords = np.full((m, 3), np.nan)
    coords[:, 0] = np.broadcast_to(x[:, 0], (m,))
    coords[:, 1] = np.broadcast_to(y[:, 0], (m,))
    if z is not None:
        coords[:, 2] = np.broadcast_to(z[:, 0], (m,))
    if scalar:
        return SliceICs(out[0], coords[0])
    return SliceICs(out, coords)


# -- slices ---------------------------------------------------------------------------------

#: The seed directions as 6-D vectors (vx, vy, vz, Lx, Ly, Lz): row i is coordinate i's.
SEED_DIRS_6D = np.concatenate([SEED_U_DIRS, SEED_L_DIRS], axis=1)
#: The seed slices' origin (U = 0, L = (0, 100, 0)).
SEED_ORIGIN_6D = np.concatenate([np.zeros(3), SEED_L_ORIGIN])


def _vec6(v, what: str) -> tuple[float, ...]:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (6,):
        raise ValueError(f"{what} must have 6 components (vx,vy,vz,Lx,Ly,Lz), got {a.size}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} is not finite")
    return tuple(float(x) for x in a)


@dataclass(frozen=True)
class Slice:
    """An affine slice of the 6-D IC space.

    ``IC = c1·d1 + c2·d2 (+ c3·d3) + origin``, evaluated left to right
    component by component (no fused multiply-add).  As in the program
    (``U = [x y]·B``, ``L = [x y]·A + L0``) the origin's U block and L block
    are each added only when they are not all zero, so a slice built from
    the seed directions reproduces :func:`seed_slice` bit for bit.

    Parameters
    ----------
    name
        A label (stored with scans).
    origin
        6 numbers (vx, vy, vz in cm/s; Lx, Ly, Lz in node-mass·cm²/s).
    directions
        1 to 3 directions, 6 numbers each (units per unit coordinate).
    l_convention
        ``"program"`` (the seed's: L is the 2019 program's, the negative of
        the physical one) or ``"physical"``: the convention of the L this
        slice produces.  Scans convert it to the preset's.
    """

    name: str
    origin: tuple[float, ...]
    directions: tuple[tuple[float, ...], ...]
    l_convention: str = "program"

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _vec6(self.origin, f"slice {self.name!r}: origin"))
        dirs = tuple(self.directions)
        if not 1 <= len(dirs) <= 3:
            raise ValueError(f"slice {self.name!r} needs 1 to 3 directions, got {len(dirs)}")
        dirs = tuple(_vec6(d, f"slice {self.name!r}: direction {i + 1}") for i, d in enumerate(dirs))
        if np.linalg.matrix_rank(np.array(dirs)) < len(dirs):
            raise ValueError(f"slice {self.name!r}: the directions are linearly dependent")
        object.__setattr__(self, "directions", dirs)
        if self.l_convention not in L_CONVENTIONS:
            raise ValueError(f"slice {self.name!r}: l_convention must be 'program' or 'physical'")

    @property
    def ndim(self) -> int:
        return len(self.directions)

    def ics(self, coords) -> np.ndarray:
        """ICs (m, 6) at slice coordinates ``coords`` (m, ndim) (or one point (ndim,) → (6,))."""
        c = np.asarray(coords, dtype=np.float64)
        one = c.ndim == 1
        c = np.atleast_2d(c)
        if c.shape[1] != self.ndim:
            raise ValueError(f"slice {self.name!r} is {self.ndim}-D: coordinates need {self.ndim} columns, got {c.shape[1]}")
        d = np.array(self.directions)
        acc = c[:, 0:1] * d[0]
        for i in range(1, self.ndim):
            acc = acc + c[:, i : i + 1] * d[i]
        o = np.array(self.origin)
        if np.any(o[:3] != 0.0):
            acc[:, :3] = acc[:, :3] + o[:3]
        if np.any(o[3:] != 0.0):
            acc[:, 3:] = acc[:, 3:] + o[3:]
        return acc[0] if one else acc

    def orthonormal(self, name: str | None = None) -> "Slice":
        """The same origin with Gram–Schmidt orthonormal directions (in the order given).

        Lengths are Euclidean in the 6 raw components (cm/s and node-mass·cm²/s
        mixed, as the writeup's section 6.2 proposes).
        """
        basis: list[np.ndarray] = []
        for d in np.array(self.directions):
            v = d.copy()
            for e in basis:  # modified Gram–Schmidt
                v = v - (v @ e) * e
            basis.append(v / np.linalg.norm(v))
        return Slice(name or f"{self.name}-ortho", self.origin, tuple(tuple(e) for e in basis), self.l_convention)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "origin": list(self.origin),
            "directions": [list(d) for d in self.directions],
            "l_convention": self.l_convention,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Slice":
        return cls(d["name"], tuple(d["origin"]), tuple(tuple(x) for x in d["directions"]), d.get("l_convention", "program"))


SEED_SLICE = Slice("seed", tuple(SEED_ORIGIN_6D), tuple(tuple(r) for r in SEED_DIRS_6D[:2]))
SEED3_SLICE = Slice("seed3", tuple(SEED_ORIGIN_6D), tuple(tuple(r) for r in SEED_DIRS_6D))

#: Named slices: the writeup's 2-D and 3-D seed slices and their orthonormal versions.
SLICES: dict[str, Slice] = {
    "seed": SEED_SLICE,
    "seed3": SEED3_SLICE,
    "seed-ortho": SEED_SLICE.orthonormal("seed-ortho"),
    "seed3-ortho": SEED3_SLICE.orthonormal("seed3-ortho"),
}


def get_slice(name: str) -> Slice:
    """A named slice (see ``SLICES``)."""
    try:
        return SLICES[name]
    except KeyError:
        raise ValueError(f"unknown slice {name!r} (choose from {', '.join(SLICES)})") from None


#: The writeup's three "red sea" topology throws on the seed slice (section 5.5).
TOPOLOGY_POINTS = ((1.65, 3.9), (1.5, 4.0), (1.2, 4.4))



# -- IC spaces --------------------------------------------------------------------------------


@dataclass
class IcBlock:
    """A contiguous range of a space's ICs.

    ``ic_id`` (m,) int64; ``index`` (m, 3) int32 grid indices i, j, k
    (k = 0 on a 2-D grid; -1 where the space is not a grid); ``coords``
    (m, 3) float64 slice coordinates (NaN beyond the slice's dimension);
    ``ics`` (m, 6) in the slice's L convention.
    """

    ic_id: np.ndarray
    index: np.ndarray
    coords: np.ndarray
    ics: np.ndarray

    def __len__(self) -> int:
        return len(self.ic_id)


def _block(ids, index, coords_nd, sl: Slice) -> IcBlock:
    m = len(ids)
    coords = np.full((m, 3), np.nan)
    coords[:, : sl.ndim] = coords_nd
    return IcBlock(ids.astype(np.int64), index.astype(np.int32), coords, sl.ics(coords_nd).reshape(m, 6))


#: Most ICs a space may hold: ``ic_id`` is int64.
MAX_ICS = 2**63 - 1
#: Most grid points per axis: grid indices are int32.
MAX_AXIS_POINTS = 2**31 - 1
#: Most points of a scrambled Sobol sample (scipy's 30 bits).
MAX_SOBOL_POINTS = 2**30


def _slice_of(s) -> "Slice":
    if isinstance(s, str):
        return get_slice(s)
    if not isinstance(s, Slice):
        raise TypeError(f"slice must be a Slice or a slice name ({', '.join(SLICES)}), got {type(s).__name__}")
    return s


def _check_range(start: int, stop: int, size: int) -> tuple[int, int]:
    start, stop = int(start), int(stop)
    if not 0 <= start <= stop <= size:
        raise ValueError(f"IC range [{start}, {stop}) outside [0, {size})")
    return start, stop


@dataclass(frozen=True)
class Grid:
    """A regular grid on a window of a slice.

    Parameters
    ----------
    slice
        The slice (a :class:`Slice` or the name of one in ``SLICES``).
    window
        ((x0, x1), (y0, y1)[, (z0, z1)]), slice coordinates, or a name.
    res
        Points per axis (nx, ny[, nz]); one int means the same on every axis;
        or their text, ``"N"`` or ``"NX,NY[,NZ]"`` (:func:`dicetrace.windows.get_res`).

    ``ic_id = (i·ny + j)·nz + k`` (row-major, x slowest); the point is
    ``(xs[i], ys[j], zs[k])`` with the axes of :meth:`axes`.
    """

    slice: Slice
    window: tuple[tuple[float, float], ...]
    res: tuple[int, ...]
    kind: str = field(default="grid", init=False)

    def __post_init__(self) -> None:
        sl = _slice_of(self.slice)
        object.__setattr__(self, "slice", sl)
        res = get_res(self.res, sl.ndim)
        object.__setattr__(self, "res", res)
        object.__setattr__(self, "window", get_window(self.window, sl.ndim, points=res))

    @property
    def ndim(self) -> int:
        return self.slice.ndim

    @property
    def shape(self) -> tuple[int, ...]:
        return self.res

    @property
    def size(self) -> int:
        """Number of grid points, exactly (a Python int, however large; a scan takes at most ``MAX_ICS``)."""
        return math.prod(self.res)

    def axes(self) -> list[np.ndarray]:
        """The coordinate vector of each axis (the program's point formula)."""
        return [grid_axis(lo, hi, n) for (lo, hi), n in zip(self.window, self.res)]

    def block(self, start: int, stop: int) -> IcBlock:
        start, stop = _check_range(start, stop, self.size)
        ids = np.arange(start, stop, dtype=np.int64)
        shape3 = tuple(self.res) + (1,) * (3 - self.ndim)
        idx = np.stack(np.unravel_index(ids, shape3), axis=1)
        axes = self.axes()
        coords = np.stack([axes[a][idx[:, a]] for a in range(self.ndim)], axis=1)
        return _block(ids, idx, coords, self.slice)

    def to_dict(self) -> dict:
        return {"kind": "grid", "slice": self.slice.to_dict(), "window": [list(w) for w in self.window], "res": list(self.res)}


SAMPLE_METHODS = ("random", "sobol")
_SAMPLE_BLOCK = 4096  # random points are drawn in fixed blocks: any range regenerates bit for bit


@dataclass(frozen=True)
class Sample:
    """``n`` points in a box of a slice: uniform random or scrambled Sobol.

    Random points come in fixed blocks of 4096 drawn with
    ``np.random.default_rng([seed, block])``; Sobol points from
    ``scipy.stats.qmc.Sobol(d, scramble=True, seed=seed)``, fast-forwarded.
    Either way any range of ids regenerates the same points, whatever the
    chunking.  Coordinates are ``lo + u·(hi − lo)``.
    """

    slice: Slice
    box: tuple[tuple[float, float], ...]
    n: int
    method: str = "random"
    seed: int = 0
    kind: str = field(default="sample", init=False)

    def __post_init__(self) -> None:
        sl = _slice_of(self.slice)
        object.__setattr__(self, "slice", sl)
        object.__setattr__(self, "box", get_window(self.box, sl.ndim))
        if not _is_count(self.n) or self.n < 1:
            raise ConfigError("n", f"sample size n must be an integer >= 1, got {_show(self.n)}")
        object.__setattr__(self, "n", int(self.n))
        if not isinstance(self.method, str) or self.method not in SAMPLE_METHODS:
            raise ConfigError("method", f"unknown sample method {_show(self.method)} (choose from {', '.join(SAMPLE_METHODS)})")
        if self.method == "sobol" and self.n > MAX_SOBOL_POINTS:
            raise ConfigError("n", f"a sobol sample has at most 2**30 = {MAX_SOBOL_POINTS:,} points, got n = {self.n:,}")
        if not _is_count(self.seed) or self.seed < 0 or self.seed >= 2**64:
            raise ConfigError("seed", f"sample seed must be an integer in [0, 2**64), got {_show(self.seed)}")
        object.__setattr__(self, "seed", int(self.seed))

    @property
    def ndim(self) -> int:
        return self.slice.ndim

    @property
    def size(self) -> int:
        return self.n

    def unit_points(self, start: int, stop: int) -> np.ndarray:
        """Points in the unit cube (stop − start, ndim)."""
        start, stop = _check_range(start, stop, self.n)
        d = self.ndim
        if self.method == "sobol":
            from scipy.stats import qmc  # scipy.stats takes seconds to import: only for a Sobol sample

            eng = qmc.Sobol(d, scramble=True, seed=self.seed)
            if start:
                eng.fast_forward(start)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # balance warnings for n not a power of 2
                return eng.random(stop - start)
        out = np.empty((stop - start, d))
        b0, b1 = start // _SAMPLE_BLOCK, (stop - 1) // _SAMPLE_BLOCK if stop > start else -1
        for b in range(b0, b1 + 1):
            u = np.random.default_rng([self.seed, b]).random((_SAMPLE_BLOCK, d))
            lo, hi = max(start, b * _SAMPLE_BLOCK), min(stop, (b + 1) * _SAMPLE_BLOCK)
            out[lo - start : hi - start] = u[lo - b * _SAMPLE_BLOCK : hi - b * _SAMPLE_BLOCK]
        return out

    def block(self, start: int, stop: int) -> IcBlock:
        start, stop = _check_range(start, stop, self.n)
        u = self.unit_points(start, stop)
        lo = np.array([w[0] for w in self.box])
        hi = np.array([w[1] for w in self.box])
        coords = lo + u * (hi - lo)
        ids = np.arange(start, stop, dtype=np.int64)
        return _block(ids, np.full((len(ids), 3), -1), coords, self.slice)

    def to_dict(self) -> dict:
        return {
            "kind": "sample",
            "slice": self.slice.to_dict(),
            "box": [list(w) for w in self.box],
            "n": self.n,
            "method": self.method,
            "seed": self.seed,
        }


@dataclass(frozen=True)
class Points:
    """Explicit points on a slice: ``coords`` (m, ndim) slice coordinates."""

    slice: Slice
    coords: tuple[tuple[float, ...], ...]
    kind: str = field(default="points", init=False)

    def __post_init__(self) -> None:
        sl = _slice_of(self.slice)
        object.__setattr__(self, "slice", sl)
        try:
            c = np.atleast_2d(np.asarray(self.coords, dtype=np.float64))
        except (TypeError, ValueError):
            raise ValueError(f"points must be numbers, {sl.ndim} per point") from None
        if c.shape[1] != sl.ndim or len(c) < 1:
            raise ValueError(f"points on the {sl.ndim}-D slice {sl.name!r} need {sl.ndim} coordinates each, got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("points have non-finite coordinates")
        object.__setattr__(self, "coords", tuple(tuple(float(v) for v in row) for row in c))

    @property
    def ndim(self) -> int:
        return self.slice.ndim

    @property
    def size(self) -> int:
        return len(self.coords)

    def block(self, start: int, stop: int) -> IcBlock:
        start, stop = _check_range(start, stop, self.size)
        ids = np.arange(start, stop, dtype=np.int64)
        c = np.array(self.coords[start:stop], dtype=np.float64).reshape(-1, self.ndim)
        return _block(ids, np.full((len(ids), 3), -1), c, self.slice)

    def to_dict(self) -> dict:
        return {"kind": "points", "slice": self.slice.to_dict(), "coords": [list(c) for c in self.coords]}


IcSpace = Grid | Sample | Points


def space_from_dict(d: dict) -> IcSpace:
    """Inverse of ``Grid/Sample/Points.to_dict``."""
    sl = Slice.from_dict(d["slice"])
    kind = d.get("kind")
    if kind == "grid":
        return Grid(sl, tuple(tuple(w) for w in d["window"]), tuple(d["res"]))
    if kind == "sample":
        return Sample(sl, tuple(tuple(w) for w in d["box"]), d["n"], d.get("method", "random"), d.get("seed", 0))
    if kind == "points":
        return Points(sl, tuple(tuple(c) for c in d["coords"]))
    raise ValueError(f"unknown IC space kind {kind!r}")
