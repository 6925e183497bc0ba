"""Wiring of the analysis callables to the simulator.

The measures of :mod:`dicetrace.analysis` that need new simulations
(:func:`~dicetrace.analysis.uncertainty.uncertainty_exponent_perturbation`,
:func:`~dicetrace.analysis.wada.wada_grid_test`,
:func:`~dicetrace.analysis.settle.bisect_boundary`,
:func:`~dicetrace.analysis.settle.settle_profile`,
:func:`~dicetrace.analysis.vertices.find_vertices`, ...) take a callable
``classify(points (n, d)) -> labels (n,)`` in slice coordinates. This module
builds such callables from a slice of initial-condition space and a model
configuration; every call runs its points through
:func:`dicetrace.simulate.simulate_batch` (numba threads), in chunks, so a
refinement level or a set of perturbations is one parallel batch.

>>> from dicetrace.analysis.simulator import classify_on_slice, settle_on_slice
>>> classify = classify_on_slice("seed")                    # the writeup's 2-D slice
>>> classify([[1.65, 3.9], [1.5, 4.0]])                     # doctest: +SKIP
array([3, 3])
>>> labels, t_s = settle_on_slice("seed", gamma=0.01)([[0.05, 0.05]])  # doctest: +SKIP

Labels are those of :class:`~dicetrace.analysis.grouping.GroupByOutcome`:
1..6 the face up, 0 undefined, -1 did not settle (time cap, non-finite state
or blow-up), or, with ``label="contact_sequence"``, the text of the ground
contact sequence (optionally reduced modulo the cube's rotations).

This module imports the simulator; the rest of :mod:`dicetrace.analysis`
does not, and it is not re-exported from the package.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from dicetrace.ics import get_slice
from dicetrace.params import Config, resolve_config
from dicetrace.simulate import simulate_batch
from dicetrace.status import Status
from dicetrace.windows import get_res, get_window, grid_axis

from .grouping import UNSETTLED_LABEL, canonical_contact_sequence

__all__ = [
    "LABEL_KINDS",
    "BATCH_POINTS",
    "SliceRun",
    "SliceClassifier",
    "SliceSettle",
    "WindowSample",
    "classify_on_slice",
    "settle_on_slice",
    "run_on_slice",
    "resolve_slice",
    "resolve_window",
    "window_axes",
    "window_points",
    "sample_window",
]

#: What a classifier returns per point.
LABEL_KINDS = ("outcome", "contact_sequence", "contact_sequence_rotations", "contact_sequence_symmetries")
#: Points per call of :func:`~dicetrace.simulate.simulate_batch` (bounds the contact-set
#: buffers; not a scan's chunk, which is ICs per Parquet file: ``dicetrace.scan.DEFAULT_CHUNK``).
BATCH_POINTS = 65536



# --------------------------------------------------------------------------
# slices and windows
# --------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _ResolvedSlice:
    name: str
    ndim: int | None  # None: a user function, any number of coordinates
    to_ics: Callable[[np.ndarray], np.ndarray]  # (n, d) -> (n, 6), in the slice's convention
    l_convention: str  # "program" or "physical"


def resolve_slice(slice_spec) -> _ResolvedSlice:
    """Turn a slice name, a slice object or a function into ``points -> ICs``.

    Parameters
    ----------
    slice_spec : str, slice object or callable
        A name known to :func:`dicetrace.ics.get_slice` (``"seed"``,
        ``"seed3"``, ``"seed-ortho"``, ...); an object with ``ics(coords)``
        and ``ndim`` (:class:`dicetrace.ics.Slice`); or a function
        ``(points (n, d)) -> ICs (n, 6)`` whose ICs are already in the
        preset's L convention.
    """
    if isinstance(slice_spec, str):
        slice_spec = get_slice(slice_spec)
    if hasattr(slice_spec, "ics") and hasattr(slice_spec, "ndim"):
        sl = slice_spec
        conv = getattr(sl, "l_convention", "program")
        return _ResolvedSlice(
            getattr(sl, "name", "slice"), int(sl.ndim), lambda p: np.asarray(sl.ics(p)).reshape(-1, 6), conv
        )
    if callable(slice_spec):
        name = getattr(slice_spec, "__name__", "function")
        return _ResolvedSlice(name, None, lambda p: np.asarray(slice_spec(p), dtype=float).reshape(-1, 6), "preset")
    raise TypeError(f"slice_spec must be a slice name, a slice object or a function, not {type(slice_spec).__name__}")


def resolve_window(window, ndim: int = 2) -> tuple[tuple[float, float], ...]:
    """Window ranges ``((x0, x1), (y0, y1)[, (z0, z1)])`` from a name, ``"x0,x1,y0,y1"`` or pairs.

    Names are the writeup's (``home``, ``zoom-out``, ``more-out``,
    ``most-out``, ``red-sea``, ``red-sea-2``, ``party``, ``green-island``)
    and the program's zooms; read and checked by the one window parser,
    :func:`dicetrace.windows.get_window`.
    """
    return get_window(window, ndim)


def window_axes(window, res) -> list[np.ndarray]:
    """Grid axes of a window with the program's formula ``x0 + (p−1)/(n−1)·(x1−x0)``.

    Parameters
    ----------
    window : str or sequence of (lo, hi)
        See :func:`resolve_window`; its length fixes the dimension.
    res : int, sequence of int, or their text
        Points per axis (read by the one resolution parser, :func:`dicetrace.windows.get_res`).
    """
    ndim = len(window) if not isinstance(window, str) else 2
    win = resolve_window(window, ndim)
    return [grid_axis(lo, hi, n) for (lo, hi), n in zip(win, get_res(res, len(win)))]


def window_points(window, res) -> tuple[np.ndarray, tuple[int, ...], list[np.ndarray]]:
    """All grid points of a window, x slowest: ``(points (n, d), shape, axes)``.

    ``labels.reshape(shape)`` of the points' labels is a label grid indexed
    ``[i, j(, k)]`` with ``i`` along x, as :mod:`dicetrace.analysis` expects.
    """
    axes = window_axes(window, res)
    mesh = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([m.ravel() for m in mesh], axis=1)
    return pts, tuple(len(a) for a in axes), axes


# --------------------------------------------------------------------------
# running points
# --------------------------------------------------------------------------


@dataclasses.dataclass
class SliceRun:
    """Summaries of the throws at some slice points (arrays aligned with ``points``).

    Attributes
    ----------
    points : (n, d) slice coordinates.
    outcome : (n,) int64 labels: 1..6, 0 undefined, -1 did not settle.
    t_settle_s : (n,) settle (or cap) time, s.
    steps : (n,) int64 steps integrated.
    status_code : (n,) int8 (0 settled, 1 time cap, 2 non-finite, 3 blow-up).
    sequences : list of str or None
        Contact sequences in the program's text form, when asked for.
    """

    points: np.ndarray
    outcome: np.ndarray
    t_settle_s: np.ndarray
    steps: np.ndarray
    status_code: np.ndarray
    sequences: list[str] | None = None

    @property
    def settled(self) -> np.ndarray:
        return self.status_code == 0


def _as_points(points, ndim: int | None) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 1:
        p = p.reshape(1, -1) if ndim is None or p.size == ndim else p.reshape(-1, ndim)
    if p.ndim != 2:
        raise ValueError(f"points must be an (n, d) array, got shape {p.shape}")
    if ndim is not None and p.shape[1] != ndim and len(p):
        raise ValueError(f"the slice is {ndim}-D: points need {ndim} columns, got {p.shape[1]}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points have non-finite coordinates")
    return p


def _resolve_config(config: Config | None, preset: str, overrides: dict) -> Config:
    """The configuration of an analysis call by the rule of every entry point (:func:`dicetrace.params.resolve_config`):
    ``config``, or ``preset`` with the options (:func:`~dicetrace.params.make_config`'s); never both."""
    return resolve_config(config, **overrides) if config is not None else resolve_config(preset=preset, **overrides)


def run_on_slice(
    points,
    slice_spec="seed",
    *,
    config: Config | None = None,
    preset: str = "seed",
    sequences: bool = False,
    chunk: int = BATCH_POINTS,
    **overrides,
) -> SliceRun:
    """Throw the die from slice points, in parallel batches.

    Parameters
    ----------
    points : array_like (n, d)
        Slice coordinates.
    slice_spec : str, slice object or callable
        See :func:`resolve_slice` (default the writeup's seed slice).
    config : Config, optional
        Model and numerics; default ``make_config(preset, **overrides)``.
    preset : str
        Preset name when no ``config`` is given.
    sequences : bool
        Also return the contact sequences (text).
    chunk : int
        Points per :func:`~dicetrace.simulate.simulate_batch` call.
    **overrides
        :class:`~dicetrace.params.Preset` fields (``gamma`` in s/cm, ``k``,
        ``mu``, ...) and the other options of :func:`~dicetrace.params.make_config`
        applied to ``preset``; with a ``config`` they are refused (it already
        fixes them: :func:`~dicetrace.params.resolve_config`).

    Returns
    -------
    SliceRun
    """
    sl = resolve_slice(slice_spec)
    cfg = _resolve_config(config, preset, overrides)
    return _run(sl, cfg, _as_points(points, sl.ndim), sequences, int(chunk))


def _run(sl: _ResolvedSlice, cfg: Config, pts: np.ndarray, sequences: bool, chunk: int) -> SliceRun:
    n = len(pts)
    outcome = np.empty(n, dtype=np.int64)
    t = np.empty(n, dtype=np.float64)
    steps = np.empty(n, dtype=np.int64)
    status = np.empty(n, dtype=np.int8)
    seqs: list[str] | None = [] if sequences else None
    for a in range(0, n, max(1, chunk)):
        b = min(n, a + chunk)
        conv = None if sl.l_convention == "preset" else sl.l_convention
        res = simulate_batch(sl.to_ics(pts[a:b]), config=cfg, l_convention=conv)
        status[a:b] = res.status_code
        outcome[a:b] = np.where(res.status_code == Status.SETTLED, res.outcome, UNSETTLED_LABEL)
        t[a:b] = res.t_settle_s
        steps[a:b] = res.steps
        if seqs is not None:
            seqs.extend(res.contact_sequences())
    return SliceRun(points=pts, outcome=outcome, t_settle_s=t, steps=steps, status_code=status, sequences=seqs)


# --------------------------------------------------------------------------
# classifiers
# --------------------------------------------------------------------------


class SliceClassifier:
    """``classify(points (n, d)) -> labels (n,)`` on a slice, by simulation.

    Build it with :func:`classify_on_slice`. Attributes ``config``, ``label``
    and ``ndim`` describe it; ``n_evals`` counts the points classified so far
    and ``n_calls`` the calls (each call is one or a few parallel batches).
    """

    def __init__(self, sl: _ResolvedSlice, config: Config, label: str, chunk: int):
        if label not in LABEL_KINDS:
            raise ValueError(f"label must be one of {', '.join(LABEL_KINDS)}, not {label!r}")
        self._slice = sl
        self.config = config
        self.label = label
        self.chunk = int(chunk)
        self.n_evals = 0
        self.n_calls = 0
        self._canon: dict[str, str] = {}

    @property
    def ndim(self) -> int | None:
        return self._slice.ndim

    @property
    def slice_name(self) -> str:
        return self._slice.name

    def run(self, points) -> SliceRun:
        """Full summaries of the throws (outcome, settle time, steps, status, sequences if labelled by them)."""
        pts = _as_points(points, self._slice.ndim)
        self.n_evals += len(pts)
        self.n_calls += 1
        return _run(self._slice, self.config, pts, self.label != "outcome", self.chunk)

    def _labels(self, r: SliceRun) -> np.ndarray:
        if self.label == "outcome":
            return r.outcome
        mode = {"contact_sequence": None, "contact_sequence_rotations": "rotations",
                "contact_sequence_symmetries": "symmetries"}[self.label]
        if mode is None:
            return np.array(r.sequences, dtype=object)
        out = []
        for s in r.sequences:
            c = self._canon.get(s)
            if c is None:
                c = self._canon[s] = canonical_contact_sequence(s, canonical=mode)
            out.append(c)
        return np.array(out, dtype=object)

    def __call__(self, points) -> np.ndarray:
        return self._labels(self.run(points))

    def __repr__(self) -> str:
        p = self.config.preset
        return (f"{type(self).__name__}(slice={self.slice_name!r}, preset={p.name!r}, gamma={p.gamma}, "
                f"label={self.label!r}, n_evals={self.n_evals})")


class SliceSettle(SliceClassifier):
    """``settle(points (n, d)) -> (labels (n,), t_settle_s (n,))``; see :func:`settle_on_slice`."""

    def __call__(self, points) -> tuple[np.ndarray, np.ndarray]:
        r = self.run(points)
        return self._labels(r), r.t_settle_s


def classify_on_slice(
    slice_spec="seed",
    *,
    config: Config | None = None,
    preset: str = "seed",
    label: str = "outcome",
    chunk: int = BATCH_POINTS,
    **overrides,
) -> SliceClassifier:
    """A classifier of slice points by simulation, for the analysis measures.

    Parameters
    ----------
    slice_spec : str, slice object or callable, default ``"seed"``
        The slice: a name (``"seed"``, ``"seed3"``, ``"seed-ortho"``, ...), a
        :class:`dicetrace.ics.Slice`, or a function ``points (n, d) -> ICs
        (n, 6)`` (in the preset's L convention).
    config : Config, optional
        Model and numerics (default: ``make_config(preset, **overrides)``).
    preset : str, optional
        Preset name when no ``config`` is given (default ``"seed"``).
    label : {"outcome", "contact_sequence", "contact_sequence_rotations", "contact_sequence_symmetries"}
        ``"outcome"`` (default): int64 labels 1..6, 0 undefined, -1 did not
        settle. The others: the contact-sequence text (object array), raw or
        reduced modulo the cube's 24 rotations / 48 symmetries.
    chunk : int, optional
        Points per batch.
    **overrides
        Preset fields, e.g. ``gamma=0.01`` (s/cm).

    Returns
    -------
    SliceClassifier
        Callable ``points (n, d) -> labels (n,)``.
    """
    sl = resolve_slice(slice_spec)
    return SliceClassifier(sl, _resolve_config(config, preset, overrides), label, chunk)


def settle_on_slice(slice_spec="seed", **options) -> SliceSettle:
    """Like :func:`classify_on_slice` (the same parameters), returning ``(labels, t_settle_s)``.

    ``t_settle_s`` is the simulated time (s) at which the stop test fired
    (or the time cap, for label -1). For
    :func:`~dicetrace.analysis.settle.settle_profile`.
    """
    c = classify_on_slice(slice_spec, **options)
    return SliceSettle(c._slice, c.config, c.label, c.chunk)


# --------------------------------------------------------------------------
# whole windows
# --------------------------------------------------------------------------


@dataclasses.dataclass
class WindowSample:
    """A window of a slice sampled on the program's grid.

    Attributes
    ----------
    labels : int64 array (nx, ny[, nz]) of outcomes (1..6, 0, -1).
    t_settle_s : float array, same shape, s.
    axes : list of 1-D arrays, slice coordinates of the grid nodes.
    window : ((x0, x1), (y0, y1)[, (z0, z1)]).
    sequences : object array of str, same shape, or None.
    wall_s : seconds of wall time the simulations took.
    """

    labels: np.ndarray
    t_settle_s: np.ndarray
    axes: list[np.ndarray]
    window: tuple[tuple[float, float], ...]
    sequences: np.ndarray | None = None
    status_code: np.ndarray | None = None
    wall_s: float = math.nan

    @property
    def extent(self) -> list[tuple[float, float]]:
        return [tuple(w) for w in self.window]

    @property
    def spacing(self) -> tuple[float, ...]:
        return tuple((a[-1] - a[0]) / (len(a) - 1) if len(a) > 1 else math.nan for a in self.axes)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.labels.shape


def sample_window(window, res, *, slice_spec="seed", **options) -> WindowSample:
    """Outcome (and settle-time) grid of a window, by simulation.

    Parameters
    ----------
    window : str or sequence of (lo, hi)
        A named window (2-D) or ranges; 3 ranges for a 3-D slice.
    res : int or sequence of int
        Points per axis (the program's grid formula).
    slice_spec, **options
        As :func:`run_on_slice` (``config``, ``preset``, ``chunk``, the
        overrides), which takes them with its defaults; ``sequences=True``
        keeps the contact sequences (memory: ~100 bytes per point).
    """
    ndim = 2 if isinstance(window, str) else len(window)
    pts, shape, axes = window_points(resolve_window(window, ndim), res)
    t0 = time.perf_counter()
    r = run_on_slice(pts, slice_spec, **options)
    wall = time.perf_counter() - t0
    seq = None
    if r.sequences is not None:
        seq = np.empty(len(pts), dtype=object)
        seq[:] = r.sequences
        seq = seq.reshape(shape)
    return WindowSample(
        labels=r.outcome.reshape(shape),
        t_settle_s=r.t_settle_s.reshape(shape),
        axes=axes,
        window=resolve_window(window, ndim),
        sequences=seq,
        status_code=r.status_code.reshape(shape),
        wall_s=wall,
    )


