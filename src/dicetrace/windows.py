"""Windows of a slice and the program's grid point formula.

A window is a box in slice coordinates, ((x0, x1), (y0, y1)[, (z0, z1)]):
a name in ``WINDOWS`` (the writeup's, the 2019 program's and the studies'
zooms on the seed slice), the text ``"x0,x1,y0,y1[,z0,z1]"`` or pairs.
:func:`get_window` is the one parser and the one rule for windows, boxes
and z ranges everywhere (finite, x1 > x0; a single value only on a grid
axis of one point), :func:`get_res` the one parser and rule for a grid's
resolution (points per axis); both raise :class:`~dicetrace.params.ConfigError`
naming ``window``, ``z`` or ``res``.  :func:`grid_axis` is the program's
point formula ``x = x0 + (p−1)/(n−1)·(x1−x0)``.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.config_values import ConfigError, show

#: Named windows on the seed slice, ((x0, x1), (y0, y1)): the writeup's eight, the program's zooms, the studies' zooms.
WINDOWS: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {
    "home": ((0.0, 0.1), (0.0, 0.1)),
    "zoom-out": ((0.0, 1.0), (0.0, 1.0)),
    "more-out": ((0.0, 10.0), (0.0, 10.0)),
    "most-out": ((0.0, 100.0), (0.0, 100.0)),
    "red-sea": ((1.0, 2.0), (3.5, 4.5)),
    "red-sea-2": ((1.4, 1.56), (3.95, 4.25)),
    "party": ((0.02, 0.026), (0.01, 0.02)),
    "green-island": ((0.055, 0.06), (0.035, 0.045)),
    # The 2019 program's own windows (its interactive scatter, interactiveScatter/scatters.pde)
    # beyond the writeup's: the zooms below party and green island (the vertex hunt).
    "party-2": ((0.0197, 0.0205), (0.0177, 0.0186)),
    "party-3": ((0.01975, 0.01984), (0.0182, 0.0183)),
    "green-island-2": ((0.057, 0.0576), (0.042, 0.044)),
    "green-island-3": ((0.05725, 0.0573), (0.04358, 0.04372)),
    "green-island-4": ((0.057266, 0.057274), (0.043615, 0.043635)),
    "green-island-5": ((0.057269, 0.0572702), (0.043621, 0.043625)),
    "green-island-6.2-4": ((0.057269466, 0.0572694705), (0.043622917, 0.043622924)),
    # Deeper red-sea zooms (study b), inside red sea 2 where its border is richest.
    "red-sea-3": ((1.40, 1.45), (3.95, 4.02)),
    "red-sea-4": ((1.405, 1.42), (3.955, 3.975)),
}


def _ranges(r, ndim: int | None, what: str) -> tuple[tuple[float, float], ...]:
    try:
        pairs = tuple((float(a), float(b)) for a, b in r)
    except (TypeError, ValueError):
        raise ConfigError(what, f"{what} must be (lo, hi) pairs, got {r!r}") from None
    if ndim is not None and len(pairs) != ndim:
        raise ConfigError(what, f"{what} needs {ndim} (lo, hi) ranges for a {ndim}-D slice, got {len(pairs)}")
    for lo, hi in pairs:
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ConfigError(what, f"{what} has a non-finite bound in {pairs}")
    return pairs


def _check_widths(pairs, points, z_apart: bool) -> None:
    """Every range must have hi > lo (the one rule for windows, boxes and z ranges everywhere); a grid axis of one
    point (``points[a] == 1``) may have lo == hi: that point is lo.  Never hi < lo."""
    for a, (lo, hi) in enumerate(pairs):
        one = points is not None and a < len(points) and points[a] == 1
        if hi > lo or (one and hi == lo):
            continue
        axis = "xyz"[a] if a < 3 else f"axis {a}"
        what = "zero" if hi == lo else "negative"
        field = "z" if a == 2 and z_apart else "window"
        raise ConfigError(field, f"the {axis} range must have {axis}1 > {axis}0 ({what} width), got {lo!r}, {hi!r}")


def get_window(window, ndim: int = 2, z_range=None, *, points=None) -> tuple[tuple[float, float], ...]:
    """Window ranges from a name in ``WINDOWS``, ``"x0,x1,y0,y1[,z0,z1]"`` or pairs.

    A named (2-D) window on a 3-D slice needs ``z_range``: (z0, z1) or the
    text ``"z0,z1"``.  Every range must be finite with hi > lo (a zero-width
    or inverted window is refused, by every command and in the API alike);
    only a grid axis of one point (``points``: the grid's points per axis)
    may have lo == hi.  Raises ConfigError naming ``window`` (or ``z``, for
    the range given apart); a message about a window given as text quotes it.
    """
    try:
        return _window(window, ndim, z_range, points)
    except ConfigError as e:
        if e.field != "window" or not isinstance(window, str) or repr(window) in e.message:
            raise
        raise ConfigError(e.fields, f"{e.message} (got {window!r})") from None


def _window(window, ndim, z_range, points):
    if isinstance(window, str):
        key = window.strip().lower().replace("_", "-").replace(" ", "-")
        if key in WINDOWS:
            pairs = WINDOWS[key]
        else:
            try:
                vals = [float(v) for v in window.split(",")]
            except ValueError:
                raise ConfigError(
                    "window", f"unknown window {window!r}: a name ({', '.join(WINDOWS)}) or x0,x1,y0,y1[,z0,z1]"
                ) from None
            if len(vals) % 2 or not 2 <= len(vals) <= 6:
                raise ConfigError("window", f"window {window!r} needs 2, 4 or 6 numbers (lo,hi per axis)")
            pairs = tuple((vals[i], vals[i + 1]) for i in range(0, len(vals), 2))
    else:
        pairs = _ranges(window, None, "window")
    pairs = tuple(pairs)
    if z_range is not None:
        if len(pairs) != 2:
            raise ConfigError("z", "a z range goes with a 2-D window (x and y ranges)")
        try:
            z = tuple(float(v) for v in (z_range.split(",") if isinstance(z_range, str) else z_range))
        except (TypeError, ValueError):
            z = ()
        if len(z) != 2:
            raise ConfigError("z", f"the z range must be two numbers z0,z1, got {show(z_range)}")
        if not (math.isfinite(z[0]) and math.isfinite(z[1])):
            raise ConfigError("z", f"the z range has a non-finite bound in {show(z_range)}")
        pairs = pairs + (z,)
    if len(pairs) == 2 and ndim == 3:
        raise ConfigError("z", "a 3-D slice needs a z range too (x0,x1,y0,y1,z0,z1, or a named window plus z0,z1)")
    pairs = _ranges(pairs, ndim, "window")
    _check_widths(pairs, points, z_range is not None)
    return pairs


def _is_count(v) -> bool:
    """A whole number (an int, a numpy integer or an integral float), not a bool."""
    if isinstance(v, (bool, np.bool_)):
        return False
    if isinstance(v, (int, np.integer)):
        return True
    return isinstance(v, (float, np.floating)) and math.isfinite(v) and float(v).is_integer()


def get_res(res, ndim: int) -> tuple[int, ...]:
    """A grid's points per axis from ``N`` (every axis), ``"NX,NY[,NZ]"`` text, an int or one per axis.

    The one reader and rule of a resolution (whole numbers >= 1, one per axis
    of the ``ndim``-D slice); ConfigError naming ``res`` otherwise.
    """
    axes = ",".join(f"N{a}" for a in "XYZ"[:ndim])
    given = res
    if isinstance(res, str):
        try:
            res = [int(p) for p in res.split(",")]
        except ValueError:
            raise ConfigError("res", f"resolution must be whole numbers, N or {axes}, got {given!r}") from None
    elif _is_count(res):
        res = [res]
    try:
        res = tuple(res)
    except TypeError:
        raise ConfigError("res", f"resolution must be an integer or one integer per axis, got {show(given)}") from None
    if any(not _is_count(r) for r in res):
        raise ConfigError("res", f"resolution must be whole numbers >= 1 on every axis, got {show(given)}")
    res = tuple(int(r) for r in res) * (ndim if len(res) == 1 else 1)
    if len(res) != ndim:
        raise ConfigError("res", f"resolution needs {ndim} numbers {axes} (or one N for every axis) for a {ndim}-D "
                                 f"slice, got {len(res)} in {show(given)}")
    if any(r < 1 for r in res):
        raise ConfigError("res", f"resolution must be >= 1 on every axis, got {show(given)}")
    return res


def grid_axis(lo: float, hi: float, n: int) -> np.ndarray:
    """The program's grid points ``lo + (p−1)/(n−1)·(hi−lo)``, p = 1..n (n = 1: ``lo``)."""
    n = int(n)
    if n < 1:
        raise ConfigError("res", f"a grid axis needs at least 1 point, got {n}")
    if n == 1:
        return np.array([float(lo)])
    p1 = np.arange(n, dtype=np.float64)  # p − 1
    return float(lo) + p1 / float(n - 1) * (float(hi) - float(lo))

