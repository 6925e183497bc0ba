"""The options several commands share: their help texts, and how their values reach the configuration.

``scan`` and ``explore`` take the same ``--device`` (where the batches
run: :mod:`dicetrace.devices`; its refusals, a
:class:`~dicetrace.devices.DeviceError`, become one line naming
``--device``, exit code 2).  ``simulate``, ``record``, ``scan`` and ``explore`` take the same model
options (``--preset``, ``--integrator``, ``--dt``, ``--t-max``, ``--tol``,
``--tol-growth``) and ``simulate`` and ``record`` the same IC options
(``--ic``, ``--slice``, ``--at``); the options those two declare alike are
typer annotations here (``DtOption``, ...), one declaration each.  The option text goes as it is to the
configuration layer (:func:`dicetrace.params.make_config`, the one parser
and validator of a configuration; :func:`dicetrace.windows.get_window` and
``get_res`` for windows and resolutions): no command checks a value itself.
What that layer refuses it raises as a :class:`~dicetrace.params.ConfigError`
naming the field; :func:`config_errors` turns it into one line naming the
option (``FIELD_OPTIONS``), exit code 2.
"""

from __future__ import annotations

import contextlib
import math
from typing import Annotated, Optional

import numpy as np
import typer

from dicetrace.body_text import BodyTextError, die_options, die_text, fmt_num, parse_body, plain_body  # noqa: F401
from dicetrace.commands._common import fail, parse_floats
from dicetrace.devices import DeviceError, device_label, resolve_device
from dicetrace.ic_arrays import IC_FIELDS
from dicetrace.ics import SLICES
from dicetrace.params import (
    INTEGRATORS,
    PRESETS,
    TOL_LOOSEST,
    TOL_MIN,
    ConfigError,
    Numerics,
    convert_l,
    get_preset,
    make_config,
)
from dicetrace.stepsize import impact_speed_cm_s

IC_HELP = (
    "One IC: VX,VY,VZ,LX,LY,LZ: centre-of-mass velocity (cm/s) and angular momentum "
    "(node-mass·cm²/s; for the seed preset in the 2019 program's sign convention)."
)
SLICE_HELP = (
    "Slice of IC space that --at (or the x,y[,z] columns of --ics) refers to: seed (the writeup's; "
    "with 3 coordinates its 3-D slice), seed3, seed-ortho or seed3-ortho."
)
AT_HELP = "X,Y (2-D) or X,Y,Z (3-D seed slice): coordinates on --slice."
PRESET_HELP = "Model preset: seed (the 2019 program, bit for bit) or physical."
INTEGRATOR_HELP = (
    f"Integrator: {', '.join(INTEGRATORS)} (default: the preset's own, "
    + ", ".join(f"{p.integrator} for {name}" for name, p in PRESETS.items()) + ")."
)
#: The integrators with error-controlled sub-steps (those that take --tol).
ADAPTIVE = ", ".join(name for name, spec in INTEGRATORS.items() if spec.adaptive)
#: The presets whose error-controlled integrators loosen their tolerance by default, as help text.
SCHEDULES = "; ".join(f"{name}: {p.default_tol:g} loosening at {p.default_tol_growth:g}/s"
                      for name, p in PRESETS.items() if p.default_tol is not None)
TOL_HELP = (
    f"{ADAPTIVE} only: local error tolerance of their sub-steps, in [{TOL_MIN:g}, 1) "
    f"(default: the preset's schedule when neither --tol nor --tol-growth is given ({SCHEDULES}), "
    f"else {Numerics.tol:g}; smaller is more accurate and slower)."
)
TOL_GROWTH_HELP = (
    f"{ADAPTIVE} only: the rate, 1/s, at which their tolerance loosens over a throw: tol·exp(RATE·t) at time t, "
    f"never looser than {TOL_LOOSEST:g} (default: the preset's schedule when neither --tol nor --tol-growth is "
    f"given ({SCHEDULES}), else 0: the same tolerance throughout; docs/model.md §9)."
)
DT_HELP = "Time step, s (default 0.001), or 'auto': chosen from the stiffness k and the fastest first impact so that the integrator stays stable; 0.001 for the error-controlled schemes, whose error control keeps them stable (refused in one line when no step fits)."
T_MAX_HELP = "Time cap, s of simulated time (default 60): a throw still moving then is 'time_cap', outcome -1."

DEVICE_HELP = (
    "Where the throws run: cpu (numba threads; the default), cuda (a CUDA GPU through numba-cuda, the "
    "package's cuda extra; refused where there is none) or auto (the GPU where numba-cuda finds one, "
    "else the CPU; one line on stderr says which)."
)

#: The options that ``simulate`` and ``record`` declare alike, as typer reads them from a parameter's annotation:
#: ``dt: DtOption = None`` is ``--dt`` with its help text, and the parameter gets the option's text (None if not given).
IntegratorOption = Annotated[Optional[str], typer.Option("--integrator", help=INTEGRATOR_HELP)]
DtOption = Annotated[Optional[str], typer.Option("--dt", help=DT_HELP)]
TMaxOption = Annotated[Optional[str], typer.Option("--t-max", help=T_MAX_HELP)]
TolOption = Annotated[Optional[str], typer.Option("--tol", help=TOL_HELP)]
TolGrowthOption = Annotated[Optional[str], typer.Option("--tol-growth", help=TOL_GROWTH_HELP)]
SliceOption = Annotated[Optional[str], typer.Option("--slice", help=SLICE_HELP)]
#: ``--integrators``: the integrator studies' other spelling of ``--integrator``, still taken but not listed by
#: ``--help`` (two names side by side make an option column that a narrow terminal cannot show whole).
IntegratorsAlias = Annotated[Optional[str], typer.Option("--integrators", hidden=True)]


DIE_HELP = ("The die's box: its three sides in cm, X,Y,Z along the body axes of faces 1|6, 2|5 and 3|4 (default: the "
            "preset's cube, 2,2,2). A box other than the cube, or a loaded die, runs on the continuous contact "
            "integrators (contact-tsit5, the physical preset's, and contact-dop853; docs/model.md, 'Bodies').")
LOAD_HELP = ("A hidden weight: W@X,Y,Z puts the share W (0 <= W < 1) of the die's mass at the body-frame point "
             "(X, Y, Z), cm from the box's centre, inside the box (e.g. 0.3@-0.9,0,0: near the middle of face 1).")
DieOption = Annotated[Optional[str], typer.Option("--die", help=DIE_HELP)]
LoadOption = Annotated[Optional[str], typer.Option("--load", help=LOAD_HELP)]


def body_overrides(die: str | None, load: str | None) -> dict:
    """The preset fields that ``--die X,Y,Z`` (sides, cm) and ``--load W@X,Y,Z`` set, or a one-line failure naming
    the option; {} when neither is given (:func:`parse_body`)."""
    try:
        return parse_body(die, load)
    except BodyTextError as e:
        fail(str(e))


def either(value: str | None, alias: str | None) -> str | None:
    """An option's value, else the value given under its other spelling."""
    return value if value is not None else alias


EVENTS_HELP = ("Record the exact contact events (the contact integrators only, e.g. the physical preset's): the contact "
               "sequence is then the sets inside the integrator's sub-steps, located where nodes enter or leave the "
               "ground, each with the time it began. The throws are the same as without it; it costs CPU time "
               "(docs/model.md 8.1).")
#: ``--events``, as ``simulate`` declares it (the times as a column) and as ``record`` does (the times on the log).
SimulateEventsOption = Annotated[bool, typer.Option(
    "--events", help=EVENTS_HELP + " A column contact_times_s gives the times (s).")]
RecordEventsOption = Annotated[bool, typer.Option(
    "--events", help=EVENTS_HELP + " The contact log puts each event on sim_time at its own time. With --scan: "
    "implied by a scan of exact events (the row is reproduced).")]
ScanEventsOption = Annotated[bool, typer.Option(
    "--events", help=EVENTS_HELP + " A column contact_times_s gives the times (s): a float64 per set, several times "
    "the disk of a row without. Part of the scan's definition.")]

#: The option that sets each field the configuration layer names in a ConfigError (``dicetrace.params``,
#: ``dicetrace.windows``, ``dicetrace.ics``, ``dicetrace.scan``).  A Preset field not here comes from the
#: preset itself, or from ``--set`` where a command has it.
FIELD_OPTIONS = {
    "preset": "--preset", "integrator": "--integrator", "dt_s": "--dt", "t_max_s": "--t-max", "tol": "--tol",
    "tol_growth": "--tol-growth", "window": "--window", "z": "--z", "res": "--res", "chunk": "--chunk",
    "n": "--n", "seed": "--seed", "method": "--sample", "points": "--points", "device": "--device",
    "events": "--events", "half_extents_cm": "--die", "load_fraction": "--load", "load_cm": "--load",
}
#: How an error naming several options shows one the user did not give.
DEFAULT_TEXT = {"--dt": f"{Numerics.dt_s:g} (the default)", "--t-max": f"{Numerics.t_max_s:g} (the default)"}


def option_line(e: ConfigError, given: dict | None = None, *, fallback: str = "--preset", **renamed) -> str:
    """The one line of a ConfigError: ``--option: message``, naming the option that sets the field at fault.

    ``renamed``: field → option where a command's option for it differs
    (``window="--box"``); ``fallback``: the option of any other field (a
    Preset field: ``--set`` or the preset).  A message that begins with the
    field's own name reads as the option's (``--dt auto: ...``); an error
    naming several options says the value of each (from ``given``, option →
    text, or the default).
    """
    table = {**FIELD_OPTIONS, **renamed}
    options = list(dict.fromkeys(table.get(f, fallback) for f in e.fields))
    msg = e.message
    if len(options) > 1:
        given = given or {}
        values = [f"{o} {given[o] if given.get(o) is not None else DEFAULT_TEXT.get(o, '')}".rstrip() for o in options]
        return f"{' with '.join(values)}: {msg}"
    word = options[0].lstrip("-").replace("-", "_")
    if msg.startswith(word + " "):
        return options[0] + msg[len(word):]
    return f"{options[0]}: {msg}"


@contextlib.contextmanager
def config_errors(given: dict | None = None, *, fallback: str = "--preset", **renamed):
    """Run the block; a ConfigError raised in it (however deep) becomes one line naming the option (exit 2),
    and so does a :class:`~dicetrace.devices.DeviceError` (``--device``: no GPU for cuda, a device name unknown)."""
    try:
        yield
    except ConfigError as e:
        fail(option_line(e, given, fallback=fallback, **renamed))
    except DeviceError as e:
        fail(f"{FIELD_OPTIONS['device']}: {e}")


def device_or_fail(device: str) -> str:
    """Where ``--device DEVICE`` runs here, as a result records it (``"cpu"`` or ``"cuda: <GPU name>"``), or a
    one-line failure naming ``--device`` (``cuda`` without a GPU).  ``auto`` says which it took, in one line."""
    with config_errors():
        return device_label(resolve_device(device))


#: A throw that may run longer than this before its time cap (at the slowest step of any integrator) needs ``--yes``.
LONG_THROW_S = 600.0
YesOption = Annotated[bool, typer.Option(
    "--yes", "-y", help=f"Run even when a throw may take over {LONG_THROW_S / 60:g} min before its time cap "
    "(Ctrl-C stops it within a second).")]


def long_throw_or_fail(cfg, yes: bool) -> None:
    """Refuse, without ``--yes``, a time cap so long that a throw may run for over ``LONG_THROW_S`` before it:
    its steps (``--t-max`` over ``--dt``) at the slowest step of any integrator (``scan.estimate.SLOWEST_STEP_S``,
    a pessimistic bound).  One line that says both, exit 2."""
    from dicetrace.scan.estimate import SLOWEST_STEP_S, human_seconds  # lazy: keeps `dicetrace --help` fast

    steps = cfg.numerics.max_steps
    worst = steps * SLOWEST_STEP_S
    if worst > LONG_THROW_S and not yes:
        fail(f"--t-max {fmt_num(cfg.numerics.t_max_s)} at --dt {fmt_num(cfg.numerics.dt_s)}: a throw may run "
             f"{steps:,} steps before its time cap, up to {human_seconds(worst)} at {SLOWEST_STEP_S * 1e6:g} µs a step; "
             "pass --yes to run it anyway (Ctrl-C stops it within a second), or a shorter --t-max")


def events_or_fail(cfg, events: bool) -> bool:
    """``--events`` checked against the configuration's integrator: one line naming it, exit 2, where it has none."""
    from dicetrace.simulate import check_events  # lazy: keeps `dicetrace --help` fast (imports numba)

    try:
        return check_events(cfg, events)
    except ValueError as exc:
        fail(f"--events: {str(exc).removeprefix('events=True: ')}")


def preset_or_fail(name: str):
    """The :class:`~dicetrace.params.Preset` named ``--preset NAME`` (looked up once a command), or a one-line failure."""
    with config_errors():
        return get_preset(name)


def build_config(
    preset, integrator: str | None, dt: str | None, t_max: str | None, ics=None, tol: str | None = None,
    overrides: dict | None = None, tol_growth: str | None = None, renamed: dict | None = None,
):
    """The Config of a command, built once from its options' text, or a one-line failure naming the option.

    ``preset``: the :class:`~dicetrace.params.Preset` (see :func:`preset_or_fail`)
    or its name; ``overrides``: its fields from ``--set``.  Every value is
    read and checked by :func:`dicetrace.params.make_config`, strictly: ``--tol``
    or ``--tol-growth`` with a fixed-step integrator is refused (it would
    have no effect).  ``renamed``: field → option where the command took a field under another option than
    ``FIELD_OPTIONS`` names (``half_extents_cm="--set"`` when ``--set half_extents_cm=...`` gave it).  ``--dt auto`` picks the step from the final model and
    the fastest first impact of ``ics`` (see ``dicetrace.stepsize.auto_dt``),
    or refuses.
    """
    given = {"--preset": getattr(preset, "name", preset), "--integrator": integrator, "--dt": dt, "--t-max": t_max,
             "--tol": tol, "--tol-growth": tol_growth}
    model = preset_or_fail(preset) if isinstance(preset, str) else preset
    with config_errors(given, fallback="--set" if overrides else "--preset", **(renamed or {})):
        model = model.with_(**overrides) if overrides else model
        v_impact = None
        if dt is not None and dt.strip().lower() == "auto" and ics is not None:
            with np.errstate(all="ignore"):
                v_impact = impact_speed_cm_s(ics, model)
            if not math.isfinite(v_impact):
                fail("--dt auto: the ICs are too fast to bound their impact speed")
        return make_config(model, integrator=integrator, dt_s=dt, t_max_s=t_max, v_impact_cm_s=v_impact, tol=tol,
                           tol_growth=tol_growth, strict=True)


# -- the IC options ----------------------------------------------------------------------------


def get_slice(name: str | None, ndim: int | None = None):
    """The named slice (``dicetrace.ics.SLICES``) with ``ndim`` coordinates, or a one-line failure.

    ``seed`` given 3 coordinates is the writeup's 3-D seed slice (``seed3``),
    as :func:`dicetrace.ics.seed_slice` with z.
    """
    if name not in SLICES:
        fail(f"--slice: unknown slice {name!r} (choose from {', '.join(SLICES)})")
    sl = SLICES[name]
    if ndim is not None and sl.ndim != ndim:
        if name == "seed" and ndim == 3 and "seed3" in SLICES:
            return SLICES["seed3"]
        fail(f"--at: slice {name!r} is {sl.ndim}-D: give {sl.ndim} coordinates ({','.join('XYZ'[: sl.ndim])}), got {ndim}")
    return sl


def slice_ics(name: str, coords: np.ndarray, l_convention: str, what: str = "--at") -> np.ndarray:
    """ICs (m, 6) of slice ``name`` at coordinates (m, ndim), in the preset's L convention.

    The seed slices give the 2019 program's L; a preset that takes the
    physical L (``physical``) gets it negated, so the throw is the same.
    """
    coords = np.asarray(coords, dtype=np.float64)
    sl = get_slice(name, coords.shape[1])
    with np.errstate(all="ignore"):  # overflow shows as a non-finite IC, refused below in one line
        ics = np.asarray(sl.ics(coords), dtype=np.float64).reshape(-1, 6)
    bad = ~np.isfinite(ics).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        at = ",".join(fmt_num(v) for v in coords[i])
        comps = ", ".join(f for f, ok in zip(IC_FIELDS, np.isfinite(ics[i])) if not ok)
        fail(f"{what} {at}: slice {name!r} gives a non-finite IC there ({comps}): the coordinates are too large")
    return convert_l(ics, sl.l_convention, l_convention)


def ic_from_options(ic: str | None, slice_name: str | None, at: str | None, l_convention: str):
    """One IC from ``--ic`` or ``--slice NAME --at X,Y[,Z]`` (in the preset's ``l_convention``).

    Returns (ic (6,), coords (k,) or None, description dict).
    """
    if ic is not None and (at is not None or slice_name is not None):
        fail("give either --ic or --slice/--at, not both")
    if ic is not None:
        vals = parse_floats(ic, 6, "--ic (VX,VY,VZ,LX,LY,LZ)")
        return np.array(vals, dtype=np.float64), None, {"kind": "ic"}
    if at is None:
        if slice_name is not None:
            fail(f"--slice {slice_name} needs --at X,Y (or X,Y,Z)")
        fail("no initial condition: give --ic VX,VY,VZ,LX,LY,LZ or --slice seed --at X,Y")
    if slice_name is None:
        fail("--at needs --slice (e.g. --slice seed --at 1.65,3.9)")
    get_slice(slice_name)
    coords = parse_floats(at, None, "--at")
    if len(coords) not in (1, 2, 3):
        fail(f"--at needs 2 (X,Y) or 3 (X,Y,Z) comma-separated numbers, got {len(coords)} in {at!r}")
    c = np.array(coords, dtype=np.float64)
    return slice_ics(slice_name, c[None, :], l_convention)[0], c, {"kind": "slice", "slice": slice_name}
