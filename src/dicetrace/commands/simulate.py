"""``dicetrace simulate``: throw the die from one IC or many and print one row per IC.

ICs come from ``--ic VX,VY,VZ,LX,LY,LZ``, from ``--slice seed --at X,Y[,Z]``,
or from ``--ics FILE.csv`` (columns ``vx,vy,vz,Lx,Ly,Lz``, or ``x,y[,z]``
with ``--slice seed``).  All ICs run in one parallel batch
(``simulate_batch``).  Output: ``--format table`` (default), ``csv`` or
``json``, on stdout or atomically into ``--out FILE``.  A file or pipe gets
every row; a terminal gets the table drawn to fit it, and beyond ``TTY_ROWS``
rows only the first ``TTY_HEAD``, the outcomes of all, and how to get them.

Exit codes: 0 done; 1 some IC ended in a numerical failure (status
``non_finite`` or ``blow_up``: the rows are still printed); 2 bad input.

The helpers here (``build_config``, ``ic_from_options``, ...) are shared with
``dicetrace record``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from dicetrace.commands._common import fail, output_file, parse_floats
from dicetrace.params import INTEGRATORS, PRESETS, TOL_LOOSEST, TOL_MIN, Numerics
from dicetrace.status import Status

FORMATS = ("table", "csv", "json")
EXIT_NUMERICAL_FAILURE = 1

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


# -- shared with `dicetrace record` ------------------------------------------------------------


def parse_positive(text: str | None, option: str, what: str) -> float | None:
    """A finite number > 0 from an option's text (None stays None)."""
    if text is None:
        return None
    try:
        v = float(text.strip())
    except ValueError:
        fail(f"{option} must be a number ({what}), got {text!r}")
    if not (math.isfinite(v) and v > 0):
        fail(f"{option} must be a finite number > 0 ({what}), got {text!r}")
    return v


def preset_or_fail(name: str):
    """The :class:`~dicetrace.params.Preset` named ``--preset NAME``, or a one-line failure."""
    from dicetrace.params import get_preset

    try:
        return get_preset(name)
    except ValueError as e:
        fail(f"--preset: {e}")


def build_config(
    preset: str, integrator: str | None, dt: str | None, t_max: str | None, ics=None, tol: str | None = None,
    overrides: dict | None = None, tol_growth: str | None = None,
):
    """The validated Config of a command, built once from the options' text, or a one-line failure.

    ``--dt auto`` picks the step from the final model (the preset with
    ``overrides`` applied) and the fastest first impact of ``ics`` (see
    ``dicetrace.params.auto_dt``), or refuses.  Values are validated where
    they enter: numbers here, everything else by ``make_config``; every
    message names the option(s) at fault.  ``--tol`` or ``--tol-growth``
    with a fixed-step integrator is refused (it would have no effect).
    """
    from dicetrace.params import INTEGRATORS, TOL_GROWTH_MAX, TOL_MIN, make_config, unknown_integrator
    from dicetrace.stepsize import impact_speed_cm_s

    base = preset_or_fail(preset)
    overrides = dict(overrides or {})
    if integrator is not None and integrator not in INTEGRATORS:
        fail(f"--integrator: {unknown_integrator(integrator)}")
    try:
        model = base.with_(**overrides) if overrides else base
    except (ValueError, TypeError) as e:
        fail(f"--set: {e}")
    v_impact = None
    dt_text = dt
    if dt is not None and dt.strip().lower() == "auto":
        dt = "auto"
        if ics is not None:
            with np.errstate(all="ignore"):
                v_impact = impact_speed_cm_s(ics, model)
            if not math.isfinite(v_impact):
                fail("--dt auto: the ICs are too fast to bound their impact speed")
    else:
        dt = parse_positive(dt, "--dt", "the time step in s, or 'auto'")
    t_max = parse_positive(t_max, "--t-max", "the time cap in s")
    tol = parse_positive(tol, "--tol", f"the local error tolerance of {ADAPTIVE}")
    integ = integrator or model.integrator
    if tol is not None and not TOL_MIN <= tol < 1:
        fail(f"--tol: tolerance tol must be a number in [{TOL_MIN:g}, 1), got {fmt_num(tol)}")
    growth = None
    if tol_growth is not None:
        try:
            growth = float(tol_growth.strip())
        except ValueError:
            fail(f"--tol-growth must be a number (a rate in 1/s), got {tol_growth!r}")
        if not (math.isfinite(growth) and 0 <= growth <= TOL_GROWTH_MAX):
            fail(f"--tol-growth must be a number in [0, {TOL_GROWTH_MAX:g}] (a rate in 1/s), got {tol_growth!r}")
    for option, value in (("--tol", tol), ("--tol-growth", growth)):
        if value is not None and not INTEGRATORS[integ].adaptive:
            fail(f"{option} {fmt_num(value)} applies only to the integrators with error-controlled sub-steps "
                 f"({ADAPTIVE}); {integ} has fixed steps: drop {option}")
    try:
        return make_config(base, integrator=integrator, dt_s=dt, t_max_s=t_max, v_impact_cm_s=v_impact, tol=tol,
                           tol_growth=growth, **overrides)
    except (ValueError, TypeError) as e:
        msg = str(e)
        if "time cap / dt" in msg or "longer than the time cap" in msg:
            fail(f"--t-max {t_max_text(t_max)} with --dt {dt_text or '0.001 (the default)'}: {msg}")
        if msg.startswith("dt auto"):
            fail(f"--dt auto: {msg[len('dt auto: '):]}" + (f" (--t-max {t_max_text(t_max)})" if t_max else ""))
        for needle, opt in (("integrator", "--integrator"), ("time step dt", "--dt"), ("time cap t_max", "--t-max"),
                            ("tol", "--tol")):
            if needle in msg:
                fail(f"{opt}: {msg}")
        fail(f"--set: {msg}" if overrides else f"--preset {preset}: {msg}")


def t_max_text(t_max) -> str:
    return "60 (the default)" if t_max is None else fmt_num(t_max)


def check_output_file(path, option: str = "--out", suffix: str | None = None):
    """The checked output Destination of ``option`` (see ``_common.output_file``), or a one-line failure.

    ``os.access`` says yes to root everywhere, even on read-only file systems;
    creating a probe file is the real test.  An existing ``path`` is untouched.
    """
    return output_file(path, option, suffix=suffix)


def get_slice(name: str | None, ndim: int | None = None):
    """The named slice (``dicetrace.ics.SLICES``) with ``ndim`` coordinates, or a one-line failure.

    ``seed`` given 3 coordinates is the writeup's 3-D seed slice (``seed3``),
    as :func:`dicetrace.ics.seed_slice` with z.
    """
    from dicetrace.ics import SLICES

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
    from dicetrace.params import convert_l

    from dicetrace.ic_arrays import IC_FIELDS

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


def fmt_num(v: float) -> str:
    """Compact number for names and tables (10 significant digits)."""
    return f"{float(v):.10g}"


# -- CSV input -----------------------------------------------------------------------------

_IC_COLS = ("vx", "vy", "vz", "lx", "ly", "lz")
_XYZ = ("x", "y", "z")


def read_ics_csv(path: Path, slice_name: str | None, l_convention: str):
    """ICs from a CSV file: columns vx,vy,vz,Lx,Ly,Lz, or x,y[,z] with a slice.

    Returns (ics (m, 6), coords (m, k) or None).  Columns are matched without
    regard to case; other columns are ignored.  When both kinds are present
    the IC columns are used and x, y, z are kept as the slice coordinates.
    """
    path = Path(path)
    if not path.exists():
        fail(f"IC file {str(path)!r} does not exist")
    if path.is_dir():
        fail(f"IC file {str(path)!r} is a folder")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        fail(f"IC file {str(path)!r} is not a UTF-8 text (CSV) file")
    except OSError as e:
        fail(f"cannot read IC file {str(path)!r}: {e.strerror}")
    rows = [r for r in csv.reader(io.StringIO(text)) if any(c.strip() for c in r)]
    if not rows:
        fail(f"IC file {str(path)!r} is empty (expected a header vx,vy,vz,Lx,Ly,Lz or x,y)")
    header = [h.strip().lower() for h in rows[0]]
    data = rows[1:]
    if not data:
        fail(f"IC file {str(path)!r} has a header but no rows")
    dup = sorted({h for h in header if header.count(h) > 1 and h in _IC_COLS + _XYZ})
    if dup:
        fail(f"IC file {str(path)!r}: repeated column(s) {', '.join(dup)}")
    has_ic = all(c in header for c in _IC_COLS)
    has_xy = "x" in header and "y" in header
    if not has_ic and not has_xy:
        fail(
            f"IC file {str(path)!r} needs columns vx,vy,vz,Lx,Ly,Lz or x,y (with --slice seed); "
            f"found {', '.join(h or '?' for h in header)}"
        )
    if not has_ic and slice_name is None:
        fail(f"IC file {str(path)!r} gives slice coordinates x,y: add --slice seed")
    if slice_name is not None:
        get_slice(slice_name)
    want = list(_IC_COLS) if has_ic else []
    coord_cols = [c for c in _XYZ if c in header] if has_xy else []
    idx = {c: header.index(c) for c in want + coord_cols}
    vals = np.empty((len(data), len(want) + len(coord_cols)))
    for i, row in enumerate(data):
        line = i + 2
        if len(row) != len(header):
            fail(f"IC file {str(path)!r}, line {line}: {len(row)} fields, the header has {len(header)}")
        for j, c in enumerate(want + coord_cols):
            cell = row[idx[c]].strip()
            try:
                v = float(cell)
            except ValueError:
                fail(f"IC file {str(path)!r}, line {line}, column {c}: not a number: {cell!r}")
            if not math.isfinite(v):
                fail(f"IC file {str(path)!r}, line {line}, column {c}: not finite: {cell!r}")
            vals[i, j] = v
    coords = vals[:, len(want) :] if coord_cols else None
    if has_ic:
        return vals[:, : len(want)], coords
    return slice_ics(slice_name, coords, l_convention, what=f"IC file {str(path)!r}, a row at"), coords


def run_ics(ics: np.ndarray, cfg):
    """Summaries of every IC as a BatchResult: one parallel batch, or a plain ``simulate`` for a single IC.

    (Both are bit-identical; the single throw skips the batch's thread start-up.)
    """
    from dicetrace.simulate import BatchResult, simulate, simulate_batch

    if len(ics) != 1:
        return simulate_batch(ics, config=cfg)
    r = simulate(ics[0], config=cfg)
    return BatchResult(
        ics=ics.copy(),
        outcome=np.array([r.outcome], dtype=np.int8),
        status_code=np.array([r.status], dtype=np.int8),
        steps=np.array([r.steps], dtype=np.int64),
        t_settle_s=np.array([r.t_settle_s]),
        set_offsets=np.array([0, len(r.contact_sets)], dtype=np.int64),
        sets=r.contact_sets,
        set_steps=r.contact_steps,
        config=cfg,
    )


# -- output ---------------------------------------------------------------------------------


def result_rows(batch, coords) -> tuple[list[str], list[list]]:
    """Column names and rows (python values) of a batch's summaries."""
    names = ["ic_id"]
    ncoord = 0 if coords is None else coords.shape[1]
    names += list(_XYZ[:ncoord])
    names += ["vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "steps", "t_settle_s", "status", "contact_sequence"]
    seqs = batch.contact_sequences()
    rows = []
    for i in range(len(batch)):
        row = [i]
        if ncoord:
            row += [float(v) for v in coords[i]]
        row += [float(v) for v in batch.ics[i]]
        row += [
            int(batch.outcome[i]),
            int(batch.steps[i]),
            float(batch.t_settle_s[i]),
            Status(int(batch.status_code[i])).label,
            seqs[i],
        ]
        rows.append(row)
    return names, rows


#: Columns right-aligned in the table.
_NUMERIC = frozenset({"ic_id", "x", "y", "z", "vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "steps", "t_settle_s"})
#: On a terminal the table shows at most this many rows (drawn to fit it); beyond, the first TTY_HEAD rows,
#: how many more there are, their outcomes, and how to get them all.
TTY_ROWS = 60
TTY_HEAD = 20


def _cells(rows) -> list[list[str]]:
    return [[fmt_num(v) if isinstance(v, float) else str(v) for v in r] for r in rows]


def plain_table(names, rows) -> str:
    """The table as fixed-width text: the columns of rich's borderless table, two spaces apart (any number of rows).

    Numbers are right-aligned, text left-aligned, no trailing spaces; it
    costs a string join per row (rich's layout engine took ~1 ms a row).
    """
    cells = _cells(rows)
    widths = [len(n) for n in names]
    for r in cells:
        for j, v in enumerate(r):
            if len(v) > widths[j]:
                widths[j] = len(v)
    right = [n in _NUMERIC for n in names]

    def line(vals) -> str:
        return "  ".join(v.rjust(w) if rj else v.ljust(w) for v, w, rj in zip(vals, widths, right)).rstrip()

    return "".join(line(r) + "\n" for r in [list(names), *cells])


def terminal_table(names, rows, stream) -> None:
    """The table on a terminal: rich's, fitted to its width; beyond TTY_ROWS rows only the first, a count and a hint."""
    from rich.console import Console
    from rich.table import Table

    shown = rows if len(rows) <= TTY_ROWS else rows[:TTY_HEAD]
    table = Table(box=None, header_style="bold", pad_edge=False)
    for n in names:
        table.add_column(n, justify="right" if n in _NUMERIC else "left", overflow="fold")
    for r in _cells(shown):
        table.add_row(*r)
    console = Console(file=stream, highlight=False)
    console.print(table)
    if len(shown) < len(rows):
        j = names.index("outcome")
        counts: dict = {}
        for r in rows:
            counts[r[j]] = counts.get(r[j], 0) + 1
        faces = ", ".join(f"{'face ' + str(k) if k > 0 else 'undefined' if k == 0 else 'not settled'}: "
                          f"{100 * v / len(rows):.1f}%" for k, v in sorted(counts.items(), key=lambda kv: (kv[0] <= 0, kv[0])))
        console.print(f"… and {len(rows) - len(shown):,} more rows (outcomes of all {len(rows):,}: {faces}).\n"
                      "All rows: --format csv or json, or --out FILE (the table, in full).", highlight=False, markup=False)


def render(names, rows, fmt: str, stream, *, meta: dict) -> None:
    """Every row, as ``fmt`` (table, csv or json), into a text stream."""
    if fmt == "csv":
        w = csv.writer(stream, lineterminator="\n")
        w.writerow(names)
        for r in rows:
            w.writerow([repr(v) if isinstance(v, float) else v for v in r])
    elif fmt == "json":
        doc = {**meta, "columns": names, "rolls": [dict(zip(names, r)) for r in rows]}
        json.dump(doc, stream, indent=1)
        stream.write("\n")
    else:
        stream.write(plain_table(names, rows))


def emit(names, rows, fmt: str, out, *, meta: dict) -> None:
    """Print the rows, or write them to ``out`` (a checked Destination or a path; atomically for a regular file)."""
    from dicetrace.sinks._common import STDOUT, write_bytes

    if out is None or str(getattr(out, "given", out)) == STDOUT:
        if fmt == "table" and sys.stdout.isatty():
            terminal_table(names, rows, sys.stdout)
            return
        out = STDOUT
    buf = io.StringIO()
    render(names, rows, fmt, buf, meta=meta)
    write_bytes(out, buf.getvalue().encode("utf-8"), what="--out")


def report_failures(statuses, what: str = "IC") -> bool:
    """One line on stderr if any run failed numerically; True if so."""
    statuses = [Status.from_label(s) if isinstance(s, str) else Status(int(s)) for s in statuses]
    bad = [s for s in statuses if s.failed]
    if not bad:
        return False
    kinds = sorted(set(bad))
    counts = ", ".join(f"{k.label}: {bad.count(k)}" for k in kinds)
    advice = kinds[0].advice
    print(
        f"dicetrace: numerical failure: {len(bad)} of {len(statuses)} {what}(s) failed ({counts}): {advice}",
        file=sys.stderr,
    )
    return True


# -- the command ----------------------------------------------------------------------------


def register(app: typer.Typer) -> None:
    @app.command("simulate")
    def simulate_cmd(
        ic: Optional[str] = typer.Option(None, "--ic", help=IC_HELP),
        slice_name: Optional[str] = typer.Option(None, "--slice", help=SLICE_HELP),
        at: Optional[str] = typer.Option(None, "--at", help=AT_HELP),
        ics: Optional[Path] = typer.Option(
            None, "--ics", help="CSV file of ICs: columns vx,vy,vz,Lx,Ly,Lz, or x,y[,z] with --slice seed."
        ),
        preset: str = typer.Option("seed", "--preset", help=PRESET_HELP),
        integrator: Optional[str] = typer.Option(None, "--integrator", help=INTEGRATOR_HELP),
        dt: Optional[str] = typer.Option(None, "--dt", help=DT_HELP),
        t_max: Optional[str] = typer.Option(None, "--t-max", help=T_MAX_HELP),
        tol: Optional[str] = typer.Option(None, "--tol", help=TOL_HELP),
        tol_growth: Optional[str] = typer.Option(None, "--tol-growth", help=TOL_GROWTH_HELP),
        fmt: str = typer.Option("table", "--format", help="Output format: table, csv or json. On a terminal a table of more "
                               f"than {TTY_ROWS} rows shows the first {TTY_HEAD} and the outcomes of all; a file "
                               "or pipe gets every row."),
        out: Optional[Path] = typer.Option(
            None, "--out", help="Write the output to this file (atomically; a device or FIFO directly; '-': stdout) "
            "instead of stdout."
        ),
    ) -> None:
        """Throw the die from one or many ICs; print outcome, steps, t_settle_s, status and contact sequence per IC.

        Exit code 1 when an IC ends in a numerical failure (non_finite, blow_up), 2 on bad input.
        """
        if fmt not in FORMATS:
            fail(f"unknown --format {fmt!r} (choose from {', '.join(FORMATS)})")
        if out is None:
            from dicetrace.sinks._common import STDOUT, _stdout_open

            if not _stdout_open():
                fail("standard output is closed: give --out FILE")
        dest = check_output_file(out if out is not None else STDOUT, "--out")
        conv = preset_or_fail(preset).l_convention
        if ics is not None:
            if ic is not None or at is not None:
                fail("give one source of ICs: --ics FILE, --ic, or --slice/--at")
            ic_arr, coords = read_ics_csv(ics, slice_name, conv)
            source = {"ics_file": str(ics)}
        else:
            one, c, desc = ic_from_options(ic, slice_name, at, conv)
            ic_arr = one[None, :]
            coords = None if c is None else c[None, :]
            source = desc
        cfg = build_config(preset, integrator, dt, t_max, ics=ic_arr, tol=tol, tol_growth=tol_growth)

        batch = run_ics(ic_arr, cfg)
        names, rows = result_rows(batch, coords)
        import dicetrace

        meta = {
            "dicetrace_version": dicetrace.__version__,
            "config": cfg.as_dict(),
            "source": {**source, **({"slice": slice_name} if slice_name else {})},
        }
        emit(names, rows, fmt, dest, meta=meta)
        if report_failures(batch.status):
            sys.exit(EXIT_NUMERICAL_FAILURE)  # (typer.Exit is swallowed outside standalone mode)
