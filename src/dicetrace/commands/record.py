"""``dicetrace record``: simulate one throw, or several to compare, and record it for Rerun (file, viewer, server).

The IC comes from ``--ic VX,VY,VZ,LX,LY,LZ``, ``--slice seed --at X,Y[,Z]``,
or ``--scan DIR --at X,Y`` (the scanned point nearest to X,Y, with the
scan's configuration: it reproduces that row exactly), or ``--rolls FILE
--ic-id N`` (row N of a rolls table or of a scan folder, from its own pose
where it has one, with the table's configuration: the row again, exactly).
The recording goes to ``--out PATH.rrd``, by default
``recordings/<name>.rrd`` where the name says what is in it: the IC
(``seed_x1.65_y3.9.rrd``, ``ic_1_2_3_4_5_6.rrd``), plus the preset,
integrator, time step, time cap and tolerances when they are not the
defaults, the optional channels, exact contact events and the comparison (:func:`default_name`).
``--parquet DIR`` also writes ``rolls.parquet``, ``contacts.parquet`` and
``trajectory.parquet`` there.  ``--events`` (the contact integrators) records
the exact contact events: the contact log puts each on ``sim_time`` at its
own time, and the Parquet tables carry the times.  Prints one summary line.

Sinks as in rerun's example scripts (``rr.script_add_args``): ``--out`` /
``--save FILE`` (the default when no other is given), ``--spawn`` (open a
viewer), ``--connect [--url URL]`` (a running viewer or gRPC server),
``--serve`` (gRPC + web viewer, until Ctrl-C or ``--serve-for`` s).  They
carry the same content and default blueprint: :mod:`dicetrace.sinks.rerun_stream`.
``--serve`` and ``--spawn`` listen on 127.0.0.1 unless ``--bind ADDR`` says otherwise.

Several ``--ic``, or ``--nudge EPS`` (a second throw from the first IC times
1 + EPS), compare throws in one recording: :mod:`dicetrace.sinks.rerun_compare`.

Exit codes: 0 done (settled or time cap); 1 numerical failure (status
``non_finite`` or ``blow_up``: the files are still written, for inspection);
2 bad input or an unreachable viewer / server (nothing written).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path
from typing import List, Optional

import typer

import numpy as np

from dicetrace.commands._common import EXIT_NUMERICAL_FAILURE, fail, output_dir, output_file, parse_floats, say
from dicetrace.commands import options as opts
from dicetrace.commands.options import AT_HELP, IC_HELP, PRESET_HELP, build_config, fmt_num, ic_from_options, preset_or_fail
from dicetrace.extras import require
from dicetrace.params import Numerics
from dicetrace.sinks._common import Staging, human_bytes
from dicetrace.sinks.rerun_channels import CHANNELS, parse_channels
from dicetrace.sinks.rerun_stream import (
    DEFAULT_PORT,
    DEFAULT_WEB_PORT,
    Stream,
    StreamError,
    check_connect,
    check_serve,
    check_spawn,
    parse_bind,
    quiet_sdk_logs,
    wait_serving,
)

DEFAULT_FOLDER = Path("recordings")


def default_name(ic, coords, desc: dict, cfg, channels=frozenset(), events: bool = False) -> str:
    """File stem saying what is in the recording: the IC, then whatever is not the default.

    The preset, the die's box and load (``--die``, ``--load``), integrator, time step, time cap, tolerance (and its growth), sub-steps when they
    are not the defaults, the optional channels (``_forces-penetration``) and ``_events`` for exact
    contact events (their contact sequence is another one): two recordings with
    different content never get the same default name, so a default-named file is only ever
    replaced by a recording of the same throw with the same content.
    """
    if desc.get("kind") == "scan":
        parts = [Path(desc["scan"]).resolve().name or "scan"] + [f"{a}{fmt_num(v)}" for a, v in zip("xyz", coords)]
    elif desc.get("kind") == "rolls":
        parts = [Path(desc["rolls"]).stem, f"id{desc['ic_id']}", desc["digest"]]
    elif desc.get("kind") == "slice":
        parts = [desc["slice"]] + [f"{a}{fmt_num(v)}" for a, v in zip("xyz", coords)]
    else:
        parts = ["ic"] + [fmt_num(v) for v in ic]
    default, num = Numerics(), cfg.numerics
    if cfg.preset.name != "seed":
        parts.append(cfg.preset.name)
    if cfg.preset.half_extents_cm is not None:  # --die: the box's sides
        parts.append("die" + "x".join(fmt_num(2.0 * h) for h in cfg.preset.half_extents_cm))
    if cfg.preset.load_fraction:  # --load
        parts.append(f"load{fmt_num(cfg.preset.load_fraction)}at" + ",".join(fmt_num(v) for v in cfg.preset.load_cm))
    if num.integrator != default.integrator:
        parts.append(num.integrator)
    if num.dt_s != default.dt_s:
        parts.append(f"dt{fmt_num(num.dt_s)}")
    if num.t_max_s != default.t_max_s:
        parts.append(f"tmax{fmt_num(num.t_max_s)}")
    if num.tol != default.tol:
        parts.append(f"tol{fmt_num(num.tol)}")
    if num.tol_growth != default.tol_growth:
        parts.append(f"tolgrowth{fmt_num(num.tol_growth)}")
    if num.substeps != default.substeps:
        parts.append(f"substeps{num.substeps}")
    if channels:
        parts.append("-".join(c for c in CHANNELS if c in channels))
    if events:
        parts.append("events")
    return "_".join(parts)


def compare_name(name: str, all_ics, eps, layout: str) -> str:
    """The default file stem of a comparison: ``<first throw's name>_nudge<EPS>`` for one nudged throw, else
    ``compare<N>_<first throw's name>_<digest of every IC>``; ``_side`` for the side-by-side layout."""
    if eps is not None and len(all_ics) == 2:
        out = f"{name}_nudge{fmt_num(eps)}"
    else:
        digest = hashlib.sha1(np.ascontiguousarray(np.stack(all_ics), dtype="<f8").tobytes()).hexdigest()[:8]
        out = f"compare{len(all_ics)}_{name}_{digest}"
    return out if layout == "overlay" else f"{out}_{layout}"


def ic_label(ic, coords, desc: dict) -> str:
    if desc.get("kind") == "scan":
        where = ", ".join(f"{a} = {fmt_num(v)}" for a, v in zip("xyz", coords))
        return f"scan {desc['scan']} (slice {desc['slice']}) at {where}, ic_id {desc['ic_id']}"
    if desc.get("kind") == "slice":
        return f"{desc['slice']} slice at " + ", ".join(f"{a} = {fmt_num(v)}" for a, v in zip("xyz", coords))
    if desc.get("kind") == "rolls":
        return f"table {desc['rolls']}, ic_id {desc['ic_id']}: " + ", ".join(fmt_num(v) for v in ic)
    return "given directly: " + ", ".join(fmt_num(v) for v in ic)


def check_output_folder(path: Path) -> Path:
    """Fail (exit 2) unless ``path`` is, or can be made, a writable folder whose table files can be written.

    Nothing is created: the folder is made when the tables are written.
    """
    path = output_dir(path, "--parquet")
    for name in ("rolls", "contacts", "trajectory"):
        dest = output_file(path / f"{name}.parquet", "--parquet")
        if dest.kind != "file":
            fail(f"--parquet {str(path)!r}: {name}.parquet is not a regular file")
    return path


def check_record_size(cfg, n_throws: int = 1, forces: bool = False) -> None:
    """Refuse, before running, throws whose recording could exceed the available memory.

    The worst case is throws that run to the time cap (:func:`dicetrace.sinks.rerun.recording_memory`, the
    bound the explorer's viewer applies too).
    """
    from dicetrace.sinks.rerun import recording_memory  # lazy: keeps `dicetrace --help` fast

    steps, need, avail = recording_memory(cfg, n_throws, forces)
    if avail is not None and need > avail:
        fail(f"--dt {fmt_num(cfg.numerics.dt_s)} / --t-max {fmt_num(cfg.numerics.t_max_s)}: a throw may run to the "
             f"time cap, {steps:,} steps, whose recording needs up to {human_bytes(need)} of memory, more than the "
             f"{human_bytes(avail)} available: use a larger --dt or a shorter --t-max")


def refuse_given(conflicting: dict, why: str) -> None:
    """Fail in one line, ``why: drop OPTIONS``, when any option of ``conflicting`` (option -> value) was given."""
    given = [opt for opt, v in conflicting.items() if v is not None]
    if given:
        fail(f"{why}: drop {', '.join(given)}")


def ic_from_scan(folder: Path, at: str | None, conflicting: dict):
    """The IC of a scanned point (nearest grid point to ``--at``) and the scan's configuration.

    Returns (ic, config, coords, description dict; its ``events``: whether the scan recorded exact contact
    events, which the recording then records too, to reproduce the row; its ``note``: the line that says which
    point was taken when ``--at`` was snapped to it, or None, said once every option has passed its checks).
    """
    if at is None:
        fail("--scan needs --at X,Y (the slice coordinates of a scanned point)")
    refuse_given(conflicting, "--scan takes the IC and the configuration from the scan")
    folder = Path(folder)
    if not folder.is_dir():
        fail(f"--scan {str(folder)!r} is not a folder")
    coords = parse_floats(at, None, "--at")
    try:
        from dicetrace.scan import ic_at, scan_definition  # lazy: keeps `dicetrace --help` fast (imports numba)

        the_ic, cfg, row = ic_at(folder, coords)
        defn = scan_definition(folder)
    except (ValueError, KeyError, OSError) as e:
        fail(f"--scan {str(folder)!r} --at {at}: {e}")
    ndim = len(coords)
    exact = np.array([row[a] for a in "xyz"[:ndim]], dtype=np.float64)
    desc = {"kind": "scan", "slice": defn.space.slice.name, "scan": str(folder), "ic_id": int(row["ic_id"]),
            "events": defn.events, "note": None}
    if not np.array_equal(exact, np.asarray(coords, dtype=np.float64)):  # snapped: say to which point
        point = ",".join(f"{v:.10g}" for v in exact)
        desc["note"] = (f"dicetrace: --scan: recording the scanned point nearest to --at {at}: {point} "
                        f"(ic_id {int(row['ic_id'])})")
    return np.asarray(the_ic, dtype=np.float64), cfg, exact, desc


def ic_from_rolls(path: Path, ic_id: int | None, conflicting: dict):
    """The IC, configuration and starting pose of row ``ic_id`` of a rolls table (a Parquet file of dicetrace's, or a
    scan folder: ``dicetrace scan``'s rows), to record that throw again.

    Returns (ic, config, orientation or None, description dict: ``kind`` "rolls", the file, the ic_id and the
    row's outcome and steps, which the replay is checked against).  The configuration is the table's metadata's
    (``tables.metadata_json``); the start height ``z0_cm`` of a row with a pose becomes the preset's.
    """
    if ic_id is None:
        fail("--rolls needs --ic-id N (the row to record)")
    refuse_given(conflicting, "--rolls takes the IC and the configuration from the table")
    import pyarrow.parquet as pq  # lazy: keeps `dicetrace --help` fast

    from dicetrace.scan.definition import config_from_dict
    from dicetrace.tables import read_metadata

    path = Path(path)
    if path.is_dir():  # a scan folder: its rows, its definition's configuration
        from dicetrace.scan.read import scan_row

        try:
            cfg, row = scan_row(path, int(ic_id))
        except (ValueError, KeyError, TypeError, OSError) as e:
            fail(f"--rolls {str(path)!r}: {' '.join(str(e).split())}")
        if row is None:
            fail(f"--ic-id {ic_id}: the scan {str(path)!r} has no row with that ic_id (yet)")
        posed = "qx" in row
    elif not path.is_file():
        fail(f"--rolls {str(path)!r} is neither a file nor a scan folder")
    else:
        try:
            meta = read_metadata(path)
            cfg = config_from_dict(meta["config"])
            names = pq.read_schema(path).names
            want = ["ic_id", "vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "steps"]
            posed = all(c in names for c in ("qx", "qy", "qz", "qw", "z0_cm"))
            table = pq.read_table(path, columns=want + (["qx", "qy", "qz", "qw", "z0_cm"] if posed else []),
                                  filters=[("ic_id", "=", int(ic_id))])
        except (ValueError, KeyError, TypeError, OSError) as e:  # no metadata, not Parquet, a config that fails its checks
            fail(f"--rolls {str(path)!r}: {' '.join(str(e).split())}")
        if table.num_rows != 1:
            fail(f"--ic-id {ic_id}: the table {str(path)!r} has {'no' if table.num_rows == 0 else table.num_rows} rows "
                 f"with that ic_id")
        row = {c: table.column(c)[0].as_py() for c in table.column_names}
    ic = np.array([row[c] for c in ("vx", "vy", "vz", "Lx", "Ly", "Lz")], dtype=np.float64)
    pose = None
    if posed:
        from dicetrace.ic_arrays import validate_orientations

        try:
            pose = validate_orientations(np.array([[row["qx"], row["qy"], row["qz"], row["qw"]]]), 1)[0]
            cfg = type(cfg)(preset=cfg.preset.with_(z0_cm=float(row["z0_cm"])), numerics=cfg.numerics)
        except ValueError as e:
            fail(f"--rolls {str(path)!r} --ic-id {ic_id}: {e}")
    import hashlib

    # the throw itself (IC, pose, height) in the default file name: two tables' rows never share one
    digest = hashlib.sha256(np.concatenate([ic, [] if pose is None else pose.ravel(),
                                            [cfg.preset.z0_cm]]).tobytes()).hexdigest()[:10]
    desc = {"kind": "rolls", "rolls": str(path), "ic_id": int(ic_id), "outcome": int(row["outcome"]),
            "steps": int(row["steps"]), "digest": digest}
    return ic, cfg, pose, desc


def parse_nudge(text: str | None) -> float | None:
    if text is None:
        return None
    try:
        eps = float(text)
    except ValueError:
        fail(f"--nudge must be a number (a relative perturbation such as 1e-6), got {text!r}")
    if not np.isfinite(eps) or abs(eps) >= 1.0:
        fail(f"--nudge must be finite and in (-1, 1), got {text!r}")
    return eps


def parse_seconds(text: str | None, option: str) -> float | None:
    if text is None:
        return None
    try:
        v = float(text)
    except ValueError:
        fail(f"{option} must be a number of seconds, got {text!r}")
    if not np.isfinite(v) or v < 0:
        fail(f"{option} must be a finite number of seconds >= 0, got {text!r}")
    return v


def check_port(port: int | None, option: str) -> None:
    if port is not None and not 0 < port < 65536:
        fail(f"{option} {port} is out of range 1..65535")


def check_sinks(spawn: bool, connect: bool, serve: bool, url, serve_for, port, web_port, bind=None):
    """The streaming sink asked for ("spawn", "connect", "serve" or None), its options checked; one-line failures."""
    chosen = [name for name, on in (("spawn", spawn), ("connect", connect), ("serve", serve)) if on]
    if len(chosen) > 1:
        fail(f"give at most one of --spawn, --connect, --serve (got {', '.join('--' + c for c in chosen)})")
    mode = chosen[0] if chosen else None
    if url is not None and mode != "connect":
        fail("--url needs --connect")
    if serve_for is not None and mode != "serve":
        fail("--serve-for needs --serve")
    if web_port is not None and mode != "serve":
        fail("--web-port needs --serve")
    if port is not None and mode not in ("spawn", "serve"):
        fail("--port needs --spawn or --serve (with --connect give --url)")
    if bind is not None and mode not in ("spawn", "serve"):
        fail("--bind needs --spawn or --serve (with --connect give --url)")
    check_port(port, "--port")
    check_port(web_port, "--web-port")
    if mode == "serve":  # its web viewer is rerun-notebook's build, which the explore extra brings
        require("explore", "record --serve (Rerun's web viewer)")
    return mode


def check_bind(bind: str | None) -> str:
    """The address --serve / --spawn listen on (default 127.0.0.1); one-line failure."""
    try:
        return parse_bind(bind)
    except ValueError as e:
        fail(f"--bind: {e}")


def register(app: typer.Typer) -> None:
    @app.command("record")
    def record_cmd(
        ic: Optional[List[str]] = typer.Option(
            None, "--ic", help=IC_HELP + " Repeat it to compare throws in one recording."
        ),
        slice_name: opts.SliceOption = None,
        at: Optional[str] = typer.Option(None, "--at", help=AT_HELP + " With --scan: a scanned point (the nearest one)."),
        scan: Optional[Path] = typer.Option(
            None, "--scan", help="A scan folder (dicetrace scan): record its point nearest to --at, with its configuration."
        ),
        rolls_file: Optional[Path] = typer.Option(
            None, "--rolls", help="A rolls table (a Parquet file of dicetrace's: dicetrace throw, record --parquet, "
            "a batch's to_arrow) or a scan folder (dicetrace scan): record its throw --ic-id N again, with the "
            "table's configuration and the throw's own starting pose (qx, qy, qz, qw, z0_cm) where the table has one."
        ),
        ic_id: Optional[int] = typer.Option(None, "--ic-id", help="With --rolls: the ic_id of the row to record."),
        nudge: Optional[str] = typer.Option(
            None, "--nudge", help="Compare with a second throw whose IC is the first one's times (1 + NUDGE), e.g. 1e-6: "
            "both dice side by side and their divergence on a log scale."
        ),
        preset: Optional[str] = typer.Option(None, "--preset", help=PRESET_HELP + " \\[default: seed]"),
        integrator: opts.IntegratorOption = None,
        dt: opts.DtOption = None,
        t_max: opts.TMaxOption = None,
        tol: opts.TolOption = None,
        tol_growth: opts.TolGrowthOption = None,
        die: opts.DieOption = None,
        load: opts.LoadOption = None,
        out: Optional[Path] = typer.Option(
            None, "--out", "--save", help="Output .rrd file (default, when no other sink is given: "
            "recordings/<name>.rrd, the name encoding the IC and every non-default option); a character device or FIFO is written directly, "
            "'-' is standard output."
        ),
        spawn: bool = typer.Option(False, "--spawn", help="Open a Rerun viewer now and stream the recording to it."),
        connect: bool = typer.Option(
            False, "--connect", help="Stream the recording to a running Rerun viewer or gRPC server at --url "
            "(exit 2 if none answers within 2 s)."
        ),
        url: Optional[str] = typer.Option(
            None, "--url", help="With --connect: its address, rerun+http://HOST:PORT/proxy or a port "
            "(default: the SDK's, HOST 127.0.0.1 and PORT 9876)."
        ),
        serve: bool = typer.Option(
            False, "--serve", help="Serve the recording over gRPC and the web viewer over HTTP (the URL is printed) "
            "until Ctrl-C or --serve-for seconds. Needs the explore extra (its web viewer)."
        ),
        serve_for: Optional[str] = typer.Option(None, "--serve-for", help="With --serve: stop after this many seconds."),
        port: Optional[int] = typer.Option(
            None, "--port", help="With --spawn or --serve: the gRPC port (default: 9876)."
        ),
        web_port: Optional[int] = typer.Option(None, "--web-port", help="With --serve: the web viewer's port (default: 9090)."),
        bind: Optional[str] = typer.Option(
            None, "--bind", "--host", help="With --serve or --spawn: the address to listen on (default 127.0.0.1: this "
            "machine only; 0.0.0.0: every interface)."
        ),
        layout: Optional[str] = typer.Option(
            None, "--layout", help="When comparing throws: overlay (default: each die where it is, the later ones "
            "drawn slightly smaller so coinciding dice do not flicker) or side (each throw beside the previous one)."
        ),
        channels: Optional[str] = typer.Option(
            None, "--channels", help="Optional channels, comma-separated (default: none, a lean recording): forces "
            "(per-node normal and friction contact forces as arrows), penetration (depth per node below the ground), "
            "velocities (node velocities as arrows), or all."
        ),
        parquet: Optional[Path] = typer.Option(
            None, "--parquet", help="Also write rolls.parquet, contacts.parquet and trajectory.parquet into this folder."
        ),
        events: opts.RecordEventsOption = False,
    ) -> None:
        """Simulate one throw (or several, to compare them) and record it for the Rerun viewer, with a default blueprint.

        Open a file with `rerun FILE.rrd`.  Sinks (as in rerun's example scripts): --out/--save FILE
        (the default when no other sink is given), --spawn, --connect [--url URL], --serve.
        Several --ic, or --nudge EPS, compare throws in one recording.  Exit code 1 on a numerical
        failure (the files are still written for inspection), 2 on bad input or an unreachable
        viewer or server.
        """
        quiet_sdk_logs()  # before rerun is imported: failures are one line of ours, not the SDK's log lines
        ics = list(ic or [])
        mode = check_sinks(spawn, connect, serve, url, serve_for, port, web_port, bind)
        host = check_bind(bind)
        serve_s = parse_seconds(serve_for, "--serve-for")
        eps = parse_nudge(nudge)
        comparing = len(ics) > 1 or eps is not None
        try:
            chans = parse_channels(channels)
        except ValueError as e:
            fail(f"--channels: {e}")
        if comparing and chans:
            fail("--channels records one throw: drop it when comparing throws (several --ic or --nudge)")
        if comparing and parquet is not None:
            fail("--parquet records one throw: drop it when comparing throws (several --ic or --nudge)")
        from dicetrace.sinks.rerun_compare import LAYOUTS  # lazy: keeps `dicetrace --help` fast (imports numba)

        if layout is not None and layout not in LAYOUTS:
            fail(f"--layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
        if layout is not None and not comparing:
            fail("--layout places compared throws: give several --ic or --nudge")
        pose = None
        if ic_id is not None and rolls_file is None:
            fail("--ic-id needs --rolls FILE (the table whose row to record)")
        if rolls_file is not None:
            if ics or slice_name is not None or at is not None or scan is not None:
                fail("give either --rolls FILE --ic-id N or --ic / --slice / --scan, not both")
            conflicting = {"--preset": preset, "--integrator": integrator, "--dt": dt, "--t-max": t_max, "--tol": tol,
                           "--tol-growth": tol_growth, "--die": die, "--load": load}
            the_ic, cfg, pose, desc = ic_from_rolls(rolls_file, ic_id, conflicting)
            note = None
            all_ics = [the_ic]
            coords = None
            labels = [ic_label(the_ic, None, desc)]
        elif scan is not None:
            if ics or slice_name is not None:
                fail("give either --scan DIR --at X,Y or --ic / --slice, not both")
            conflicting = {"--preset": preset, "--integrator": integrator, "--dt": dt, "--t-max": t_max, "--tol": tol,
                           "--tol-growth": tol_growth, "--die": die, "--load": load}
            the_ic, cfg, coords, desc = ic_from_scan(scan, at, conflicting)
            note = desc.pop("note")
            events = events or desc["events"]  # the scan's rows hold exact events: so does their replay
            all_ics = [the_ic]
            labels = [ic_label(the_ic, coords, desc)]
        else:
            model = preset_or_fail(preset or "seed")  # looked up once: its L convention reads the ICs, then the config
            conv = model.l_convention
            if len(ics) > 1 and (slice_name is not None or at is not None):
                fail("give either several --ic or --slice/--at, not both")
            the_ic, coords, desc = ic_from_options(ics[0] if ics else None, slice_name, at, conv)
            all_ics = [the_ic] + [ic_from_options(t, None, None, conv)[0] for t in ics[1:]]
            labels = [ic_label(the_ic, coords, desc)] + [ic_label(v, None, {"kind": "ic"}) for v in all_ics[1:]]
        if eps is not None:
            all_ics.append(all_ics[0] * (1.0 + eps))
            labels.append(f"throw 1's IC × (1 + {eps:g})")
        if scan is None and rolls_file is None:
            cfg = build_config(model, integrator, dt, t_max, ics=np.stack(all_ics), tol=tol,
                               tol_growth=tol_growth, overrides=opts.body_overrides(die, load))
        events = opts.events_or_fail(cfg, events)
        name = default_name(the_ic, coords, desc, cfg, chans, events)
        if comparing:
            name = compare_name(name, all_ics, eps, layout or "overlay")
        if out is None and mode is None:
            out = DEFAULT_FOLDER / f"{name}.rrd"
        dest = None if out is None else output_file(out, "--out", suffix=".rrd")
        if parquet is not None:
            check_output_folder(parquet)
            if dest is not None and dest.target is not None and os.path.realpath(parquet) == os.path.realpath(dest.target):
                fail(f"--out {str(out)!r} and --parquet {str(parquet)!r} are the same path")
        try:
            if mode == "connect":
                target = check_connect(url)
            elif mode == "serve":
                check_serve(port or DEFAULT_PORT, web_port or DEFAULT_WEB_PORT, host)
            elif mode == "spawn":
                check_spawn(port or DEFAULT_PORT, host)
        except StreamError as e:
            fail(str(e))
        except ValueError as e:
            fail(f"--url {url}: {e}")
        check_record_size(cfg, len(all_ics), "forces" in chans)
        if scan is not None and note is not None:  # every option checked: no line before a refusal
            say(note)

        from dicetrace.simulate import Record, simulate  # lazy: keeps `dicetrace --help` fast (imports numba)

        rec_what = Record(states=True, energy=True, forces="forces" in chans, events=events)
        rolls = [simulate(v, config=cfg, record=rec_what, orientation=pose) for v in all_ics]
        if rolls_file is not None and (rolls[0].outcome, rolls[0].steps) != (desc["outcome"], desc["steps"]):
            say(f"dicetrace: --rolls: the throw replayed ends otherwise than its row says (outcome {rolls[0].outcome}, "
                f"{rolls[0].steps} steps against {desc['outcome']}, {desc['steps']}): the table was written by "
                "another version or machine")
        roll = rolls[0]
        label = labels[0]

        if comparing:
            # lazy: keeps `dicetrace --help` fast (imports numba)
            from dicetrace.sinks.rerun_compare import compare_blueprint, compare_logger

            lay = layout or "overlay"
            log, blueprint = compare_logger(rolls, labels, name=name, layout=lay), compare_blueprint(rolls, lay)
        else:
            # lazy: keeps `dicetrace --help` fast (imports numba)
            from dicetrace.sinks.rerun import default_blueprint, roll_logger

            log = roll_logger(roll, name=name, ic_label=label, channels=chans)
            blueprint = default_blueprint(roll, chans)

        written = []
        if dest is not None:
            from dicetrace.sinks.rerun import encode_rrd  # lazy: keeps `dicetrace --help` fast (imports numba)

            # Everything is staged first and put in place together: a failure (a full
            # disk) leaves neither a half-written file nor a recording without its tables.
            with Staging() as staging:
                data = encode_rrd(log, blueprint)
                tmp = staging.path(dest)
                try:
                    tmp.write_bytes(data)
                except OSError as e:
                    raise staging.fail(dest, e) from None
                written = [dest.label if dest.kind == "stdout" else str(out)]
                if parquet is not None:
                    # lazy: keeps `dicetrace --help` fast (imports numba)
                    from dicetrace.sinks.parquet import write_tables

                    meta = {"ic_label": label, **{k: v for k, v in desc.items() if k != "kind"}}
                    ids = [desc["ic_id"]] if "ic_id" in desc else None
                    coords2 = None if coords is None else coords[None, :]
                    paths = write_tables(parquet, roll, coords=coords2, ic_ids=ids, metadata=meta, staging=staging)
                    written.append(f"{parquet}{os.sep} ({', '.join(p.name for p in paths.values())})")

        # the recording itself may be on stdout: the summary then goes to stderr
        stream_out = sys.stderr if (dest is not None and dest.kind == "stdout") or sys.stdout is None else sys.stdout

        def summary_line(sent: str = "") -> str:
            outcomes = []
            for k, r in enumerate(rolls):
                o = r.outcome if r.outcome >= 0 else "-1 (not settled)"
                pre = f"throw {k + 1}: " if comparing else ""  # numbered from 1, as the recording
                outcomes.append(f"{pre}outcome {o}  status {r.status}  steps {r.steps}  t_settle_s {r.t_settle_s:.6g}  "
                                f"contact_sequence {r.contact_sequence}")
            return ("  |  ".join(outcomes) + (f"  wrote {' '.join(written)}" if written else "")
                    + (f"  {sent}" if sent else ""))

        sent = ""
        said = False
        if mode is not None:
            st = Stream(blueprint)
            try:
                if mode == "connect":
                    st.connect(target)
                elif mode == "spawn":
                    st.spawn(port or DEFAULT_PORT, host)
                else:
                    web = st.serve(port or DEFAULT_PORT, web_port or DEFAULT_WEB_PORT, host)
                st.send(log)
                sent = f"sent to {st.grpc_url}"
                if mode == "serve":
                    until = "Ctrl-C" if serve_s is None else f"{serve_s:g} s have passed (or Ctrl-C)"
                    try:  # from here on Ctrl-C means "stop serving": a normal end, wherever it lands
                        print(summary_line(sent), file=stream_out, flush=True)  # the outcome first, then the URL
                        said = True
                        print(f"serving the web viewer at {web} (gRPC {st.grpc_url}) until {until}", file=stream_out,
                              flush=True)
                        wait_serving(serve_s)
                    except KeyboardInterrupt:
                        pass
                st.close()  # bounded: the recording handed over, or one line
            except StreamError as e:
                fail(str(e))
            finally:
                try:
                    st.close()  # after a failure: given up within the same bound, its error already said
                except (KeyboardInterrupt, StreamError):  # a Ctrl-C while the server shuts down (serving has ended)
                    pass

        if not said:
            print(summary_line(sent), file=stream_out)
        failed = [r for r in rolls if r.status.failed]
        if failed:
            r = failed[0]
            print(
                f"dicetrace: numerical failure: status {r.status} after {r.steps} steps "
                f"(t = {r.t_settle_s:.6g} s): {r.status.advice}; "
                f"the recording was still written for inspection: {' '.join(written + [sent]).strip()}",
                file=sys.stderr,
            )
            sys.exit(EXIT_NUMERICAL_FAILURE)
