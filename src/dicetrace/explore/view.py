"""The explorer's view: what one map shows, parsed and validated from URL query parameters.

A :class:`View` is a slice, a 2-D window of it (``x0,x1,y0,y1``; the third
coordinate ``z`` of a 3-D slice is fixed per view), a resolution and a
configuration (preset, integrator, damping γ, time step, and the die: ``die``
its sides X,Y,Z in cm and ``load`` W@X,Y,Z, as ``--die`` and ``--load`` give
them), built once with the view (:meth:`View.config`).  It round-trips through a URL query
(:meth:`View.to_query` / :func:`view_from_query`), so a view can be shared
and reopened.  The window and resolution are read by the one parser of
each (:func:`dicetrace.windows.get_window`, ``get_res``), the configuration
checked by :func:`dicetrace.params.make_config`; what they refuse (a
:class:`~dicetrace.params.ConfigError` naming its field) and the
explorer's own limits raise :class:`ViewError` naming the parameter, never
anything else.

Zooming stops at the float64 limit of the slice coordinates: adjacent
pixels must be at least ``MIN_ULPS_PER_PIXEL`` units in the last place apart
(at x ≈ 1.5, ulp = 2.2e-16, so a 256-pixel window is at least ~2e-12 wide).
Beyond that neighbouring pixels would be the same IC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from urllib.parse import urlencode

from dicetrace.ics import SLICES, Grid, get_slice
from dicetrace import params
from dicetrace.body_text import BodyTextError, fmt_num, parse_body, plain_body
from dicetrace.params import ConfigError
from dicetrace.windows import WINDOWS, get_res, get_window

#: Largest resolution per axis (a 1024×1024 map is ~1M throws, ~10 s on 2 cores for ``seed``).
MAX_RES = 1024
#: Smallest resolution per axis.
MIN_RES = 2
DEFAULT_RES = 256
#: Adjacent pixels at least this many units in the last place apart (the zoom limit).
MIN_ULPS_PER_PIXEL = 8
#: Largest |coordinate| of a window.
MAX_COORD = 1e6
#: Smallest and largest time step, s.
DT_RANGE = (1e-7, 0.01)
#: Smallest and largest damping γ, s/cm.
GAMMA_RANGE = (0.0, 1.0)


class ViewError(ValueError):
    """A view parameter is malformed or out of range; ``param`` names it."""

    def __init__(self, param: str, message: str):
        super().__init__(f"{param}: {message}")
        self.param = param
        self.message = message


@dataclass(frozen=True)
class View:
    """One map of the explorer.

    ``window`` is ((x0, x1), (y0, y1)) in slice coordinates, ``res`` (nx, ny)
    the grid points per axis (the program's formula, so a view is exactly a
    ``dicetrace scan`` grid), ``z`` the third coordinate of a 3-D slice.
    ``window`` may also be a name or ``"x0,x1,y0,y1"``, ``res`` ``"N"`` or
    ``"NX,NY"``: they are read into those forms.  ``gamma`` and ``dt`` None
    mean the preset's and the default.  ``die``: the sides (X, Y, Z) of the
    box, cm, or their text ``"X,Y,Z"`` (None: the preset's cube); ``load``:
    (W, X, Y, Z), a share W of the mass at the body-frame point (X, Y, Z),
    or its text ``"W@X,Y,Z"`` (None: none).  A box or loaded die runs on the
    continuous contact integrators (the ``physical`` preset's).
    """

    slice: str = "seed"
    window: tuple[tuple[float, float], tuple[float, float]] = WINDOWS["red-sea"]
    res: tuple[int, int] = (DEFAULT_RES, DEFAULT_RES)
    preset: str = "seed"
    integrator: str | None = None
    gamma: float | None = None
    dt: float | None = None
    z: float | None = None
    die: tuple[float, float, float] | None = None
    load: tuple[float, float, float, float] | None = None
    _config: object = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "window", _read("window", get_window, self.window, 2))
        object.__setattr__(self, "res", _read("res", get_res, self.res, 2))
        object.__setattr__(self, "die", _body_value("die", self.die, 3))
        object.__setattr__(self, "load", _body_value("load", self.load, 4))
        _validate(self)
        object.__setattr__(self, "_config", _make_config(self))

    # -- derived -----------------------------------------------------------------------

    @property
    def ndim(self) -> int:
        return SLICES[self.slice].ndim

    def config(self):
        """The :class:`~dicetrace.params.Config` of this view (built once, with the view)."""
        return self._config

    def grid(self, res: tuple[int, int] | None = None) -> Grid:
        """The IC grid of this view (at ``res``, default the view's); a 3-D slice gets z0 = z1 = z, nz = 1."""
        nx, ny = res or self.res
        sl = get_slice(self.slice)
        if sl.ndim == 3:
            return Grid(sl, self.window + ((self.z, self.z),), (nx, ny, 1))
        return Grid(sl, self.window, (nx, ny))

    def coarse(self, factor: int = 4) -> "View":
        """The same window at about 1/``factor`` of the resolution (a first, quick pass): :func:`pass_res` per axis."""
        return replace(self, res=tuple(pass_res(n, factor) for n in self.res))

    def zoomed(self, x0: float, x1: float, y0: float, y1: float) -> "View":
        return replace(self, window=((float(x0), float(x1)), (float(y0), float(y1))))

    def key(self) -> tuple:
        """Hashable identity (what a cached map is keyed by)."""
        return (self.slice, self.window, self.res, self.preset, self.integrator, self.gamma, self.dt, self.z,
                self.die, self.load)

    def to_query(self) -> dict[str, str]:
        """URL query parameters that :func:`view_from_query` turns back into this view."""
        (x0, x1), (y0, y1) = self.window
        q = {
            "slice": self.slice,
            "window": ",".join(repr(float(v)) for v in (x0, x1, y0, y1)),
            "res": f"{self.res[0]},{self.res[1]}",
            "preset": self.preset,
        }
        for name in ("integrator", "gamma", "dt", "z"):
            v = getattr(self, name)
            if v is not None:
                q[name] = v if isinstance(v, str) else repr(float(v))
        text = body_texts(self)
        q.update({name: t for name, t in text.items() if t is not None})
        return q

    def query_string(self) -> str:
        return urlencode(self.to_query())

    def pixel(self, x: float, y: float) -> tuple[int, int]:
        """Grid indices (i, j) of the grid point nearest to slice coordinates (x, y)."""
        out = []
        for v, (lo, hi), n in zip((x, y), self.window, self.res):
            t = (v - lo) / (hi - lo) * (n - 1)
            out.append(int(min(max(round(t), 0), n - 1)))
        return out[0], out[1]


def pass_res(n: int, factor: int) -> int:
    """A coarse pass's points on an axis of ``n``: about n/``factor``, and a subgrid of the n points if one is near.

    With c − 1 dividing n − 1 every (n−1)/(c−1)-th point of the full grid is a
    point of the coarse one, bit for bit (the grid formula divides the same
    rational), so the refined pass takes those results instead of computing
    them again: 256 → 52 and 16.  Otherwise ⌈n/factor⌉.
    """
    target = n / factor
    near = [(n - 1) // d + 1 for d in range(1, n) if (n - 1) % d == 0]
    near = [c for c in near if MIN_RES <= c < n and target / 2 <= c <= target * 1.25]
    if near:
        return min(near, key=lambda c: abs(math.log(c / target)))
    return max(MIN_RES, -(-n // factor))


def body_texts(v: View) -> dict:
    """The view's die and load as ``--die`` and ``--load`` write them (``"2,2,3"``, ``"0.3@-0.9,0,0"``; None where
    not given)."""
    die = None if v.die is None else ",".join(fmt_num(x) for x in v.die)
    load = None if v.load is None else f"{fmt_num(v.load[0])}@" + ",".join(fmt_num(x) for x in v.load[1:])
    return {"die": die, "load": load}


def _body_value(param: str, value, count: int):
    """``die`` (sides X, Y, Z) or ``load`` (W, X, Y, Z) as numbers, from their text (read by ``--die`` and
    ``--load``'s one reader, :func:`dicetrace.body_text.parse_body`) or numbers; ViewError naming it."""
    if value is None or value == "":
        return None
    if not isinstance(value, str):
        try:
            nums = tuple(float(x) for x in value)
        except (TypeError, ValueError):
            raise ViewError(param, f"must be {count} numbers, got {value!r}") from None
        value = ",".join(repr(x) for x in nums) if param == "die" or len(nums) != 4 else \
            f"{nums[0]!r}@{nums[1]!r},{nums[2]!r},{nums[3]!r}"
    value = str(value)[:200]
    try:
        fields = parse_body(value, None) if param == "die" else parse_body(None, value)
    except BodyTextError as e:
        raise ViewError(param, e.message) from None
    if param == "die":
        return tuple(2.0 * h for h in fields["half_extents_cm"])
    return (fields["load_fraction"], *fields["load_cm"])


def _num(param: str, text) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ViewError(param, f"must be a number, got {str(text)[:60]!r}") from None
    if not math.isfinite(v):
        raise ViewError(param, f"must be finite, got {text!r}")
    return v


def _read(param: str, parse, value, ndim: int):
    """``value`` read by its one parser (``get_window``, ``get_res``); what it refuses becomes a ViewError."""
    try:
        return parse(value, ndim)
    except ConfigError as e:
        raise ViewError(param, e.message) from None


def _validate(v: View) -> None:
    """The explorer's own limits (what it computes live); the configuration is the configuration layer's."""
    if v.slice not in SLICES:
        raise ViewError("slice", f"unknown slice {v.slice!r} (choose from {', '.join(SLICES)})")
    for r in v.res:
        if not MIN_RES <= r <= MAX_RES:
            raise ViewError("res", f"must be between {MIN_RES} and {MAX_RES} per axis, got {v.res[0]},{v.res[1]}")
    for axis, (lo, hi), n in zip("xy", v.window, v.res):
        for b in (lo, hi):
            if abs(b) > MAX_COORD:
                raise ViewError("window", f"{axis} bounds must be within ±{MAX_COORD:g}, got {lo!r}, {hi!r}")
        ulp = math.ulp(max(abs(lo), abs(hi)))
        if (hi - lo) / (n - 1) < MIN_ULPS_PER_PIXEL * ulp:
            raise ViewError(
                "window",
                f"the {axis} range {lo!r}..{hi!r} is at the float64 limit: {n} pixels need a width of at least "
                f"{MIN_ULPS_PER_PIXEL * ulp * (n - 1):.3g} here (adjacent pixels {MIN_ULPS_PER_PIXEL} ulp apart)",
            )
    ndim = SLICES[v.slice].ndim
    if ndim == 3 and v.z is None:
        raise ViewError("z", f"the 3-D slice {v.slice!r} needs its third coordinate z")
    if ndim != 3 and v.z is not None:
        raise ViewError("z", f"the slice {v.slice!r} is 2-D: z applies only to a 3-D slice")
    if v.z is not None and (not math.isfinite(v.z) or abs(v.z) > MAX_COORD):
        raise ViewError("z", f"must be a finite number within ±{MAX_COORD:g}, got {v.z!r}")
    if v.gamma is not None and not GAMMA_RANGE[0] <= v.gamma <= GAMMA_RANGE[1]:
        raise ViewError("gamma", f"the damping γ must be in [{GAMMA_RANGE[0]:g}, {GAMMA_RANGE[1]:g}] s/cm, got {v.gamma!r}")
    if v.dt is not None and not DT_RANGE[0] <= v.dt <= DT_RANGE[1]:
        raise ViewError("dt", f"the time step must be in [{DT_RANGE[0]:g}, {DT_RANGE[1]:g}] s, got {v.dt!r}")


#: The query parameter that sets each field a ConfigError names (any other: the preset's).
CONFIG_PARAMS = {"preset": "preset", "integrator": "integrator", "dt_s": "dt", "gamma": "gamma",
                 "half_extents_cm": "die", "load_fraction": "load", "load_cm": "load"}


def _make_config(v: View):
    """The view's Config, by :func:`dicetrace.params.make_config` (the one validator); its ConfigError as a ViewError
    naming the query parameter.  Its die is written one way (``plain_body``: the sides of the preset's cube are the
    cube), as a scan writes it."""
    overrides = {} if v.gamma is None else {"gamma": v.gamma}
    text = body_texts(v)
    overrides.update(parse_body(text["die"], text["load"]))
    try:
        cfg = params.make_config(v.preset, integrator=v.integrator, dt_s=v.dt, **overrides)
    except ConfigError as e:
        raise ViewError(CONFIG_PARAMS.get(e.field, "preset"), e.message) from None
    return replace(cfg, preset=plain_body(cfg.preset))


#: The query parameters a view reads.
VIEW_PARAMS = ("slice", "window", "res", "preset", "integrator", "gamma", "dt", "z", "die", "load")


def view_from_query(q, default: View | None = None) -> View:
    """A :class:`View` from URL query parameters (a mapping); absent ones keep ``default``'s.

    Raises :class:`ViewError` naming the first bad parameter.
    """
    base = default or View()
    kw = {}
    if "slice" in q:
        kw["slice"] = str(q["slice"])
    for name in ("window", "res"):  # read by View, with their one parsers
        if name in q:
            kw[name] = str(q[name])
    if "preset" in q:
        kw["preset"] = str(q["preset"])
    for name in ("integrator", "die", "load"):
        if name in q:
            kw[name] = str(q[name]) or None
    for name in ("gamma", "dt", "z"):
        if name in q:
            kw[name] = None if q[name] in ("", "default") else _num(name, q[name])
    slice_name = kw.get("slice", base.slice)
    if slice_name in SLICES and SLICES[slice_name].ndim == 3 and kw.get("z", base.z) is None and "z" not in q:
        kw["z"] = 0.0
    if slice_name in SLICES and SLICES[slice_name].ndim != 3 and "z" not in q:
        kw["z"] = None
    try:
        return replace(base, **kw)
    except ViewError:
        raise
    except (TypeError, ValueError) as e:  # pragma: no cover - every field is checked in _validate
        raise ViewError("view", str(e)) from None
