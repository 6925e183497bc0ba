"""``dicetrace analyze NAME``: the one door of every study of :mod:`dicetrace.studies`.

Examples::

    dicetrace analyze all --quick                 # CI-sized, into ./dicetrace-results/analysis
    dicetrace analyze cells --quick --out /tmp/q  # one writeup study
    dicetrace analyze all --out analysis          # regenerate the committed full results (repository root)
    dicetrace analyze --report-only --out analysis   # re-assemble analysis/REPORT.md only
    dicetrace analyze accuracy --quick            # an integrator study, into ./dicetrace-results/accuracy
    dicetrace analyze friction --out analysis/accuracy   # regenerate the committed v_reg.csv, v_reg.md
    dicetrace analyze cuboids --out analysis/cuboids     # physical against real cuboid dice (committed)
    dicetrace analyze bars --out analysis/bars           # long bars against Pender & Uhrin (committed)
    dicetrace analyze aspect --out analysis/aspect       # the home window against the aspect (committed)

Writeup studies: the names and letters of :data:`dicetrace.studies.WRITEUP_STUDIES` and
:data:`~dicetrace.studies.LETTERS` (``dicetrace analyze --help`` lists them, from cells (a) to the
latest), or ``all``; several at once share one output folder.  Integrator
studies: accuracy, stability, friction, cuboids, bars, aspect, each run alone with options of its own
(:mod:`dicetrace.commands.accuracy`; ``dicetrace accuracy`` and ``dicetrace
stability`` are aliases kept from before).  An option the named study does not
take (:data:`TAKES`) is refused by name.

Output of the writeup studies: ``--out`` (default ``./dicetrace-results/analysis``) gets
``figures/``, ``results/<study>.json``, ``cache/`` (simulated grids as plain
arrays, never unpickled; a file that is not one of them is ignored and its
grid simulated again) and ``REPORT.md``: the whole report once every study
has results there, else only the sections of the studies that have (one study
into a new folder: its own section, with its numbers and run time).  A
folder of committed results (``analysis/``, marked by
``.committed-results``) only takes full runs: ``--quick``, ``--res`` or
``--seed`` into it is refused (and so is a reduced integrator study).

Every option is checked before anything is written or computed (``--res``
>= 3 and a largest grid that fits the memory available, ``--seed`` in
[0, 2**64), a known ``--integrator``, a finite ``--tol`` in [1e-14, 1) with
which the converged models can run; the integrator studies' own options in
:mod:`dicetrace.commands.accuracy`); a bad one is one line naming it, exit 2,
and ``--out`` is not created.

Exit codes: 0 done; 2 bad input (an option above, unknown study, an option the
study does not take, unwritable output, a CI-sized run into committed results).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from dicetrace.commands._common import fail
from dicetrace.commands.accuracy import (command_line, run_accuracy, run_aspect, run_bars, run_cuboids, run_friction,
                                         run_stability)
from dicetrace.commands.options import IntegratorsAlias, config_errors, either
from dicetrace.devices import resolve_device
from dicetrace.extras import require
from dicetrace.studies import INTEGRATOR_STUDIES, INTEGRATOR_TITLES, LETTERS, TITLES, resolve
from dicetrace.studies import runner as studies_runner
from dicetrace.studies import study_accuracy as acc
from dicetrace.studies.context import DEFAULT_SEED, Options
from dicetrace.studies.outputs import default_out, prepare_out
from dicetrace.studies.report import build as build_report
from dicetrace.studies.study_converged import check_overrides

#: The studies as ``analyze --help`` lists them: letter (writeup studies), name, what it is about.
#: (Two spaces at least between the fields: ``--help`` wraps each row with its title hanging under its start.)
_NAME_W = max(map(len, [*LETTERS.values(), *INTEGRATOR_STUDIES])) + 2
STUDIES_HELP = "\n".join(f"  {letter}  {name:<{_NAME_W}}{TITLES[name]}" for letter, name in LETTERS.items())
INTEGRATOR_HELP = "\n".join(f"     {name:<{_NAME_W}}{INTEGRATOR_TITLES[name]}" for name in INTEGRATOR_STUDIES)

#: The options each kind of study takes ("writeup": every writeup study; the others by name).
TAKES = {
    "writeup": ("--quick", "--out", "--res", "--seed", "--integrator", "--tol", "--device", "--no-cache", "--no-report"),
    "accuracy": ("--quick", "--out", "--window", "--n", "--seed", "--presets", "--integrator", "--threads", "--quiet"),
    "stability": ("--quick", "--out", "--presets", "--integrator", "--k", "--quiet"),
    "friction": ("--quick", "--out", "--quiet"),
    "cuboids": ("--quick", "--out", "--threads", "--quiet"),
    "bars": ("--quick", "--out", "--threads", "--quiet"),
    "aspect": ("--quick", "--out", "--threads", "--quiet"),
}


def _takes_help() -> str:
    return "\n".join(f"  {kind + ':':<11}  {' '.join(opts)}" for kind, opts in TAKES.items())


def _help() -> str:
    return f"""Run a study (figures, numbers, tables) into ./dicetrace-results/... or --out.

The writeup studies: name each by its name or its letter (the prefix of its
figures, figures/a_*.png ...), several at once, or give all; they share one
output folder (default ./dicetrace-results/analysis) and its REPORT.md:

{STUDIES_HELP}

The writeup studies need dicetrace's analysis extra (scikit-image).

The integrator studies, each run alone with options of its own (default
output ./dicetrace-results/NAME):

{INTEGRATOR_HELP}

The options each study takes (any other is refused):

{_takes_help()}

The committed results in analysis/ are regenerated only by full runs from the
repository root: `dicetrace analyze all --out analysis`, and `dicetrace analyze
accuracy|stability|friction --out analysis/accuracy` and `dicetrace analyze
cuboids|bars|aspect --out analysis/NAME`; a --quick or otherwise
reduced run into analysis/ is refused. REPORT.md is the whole report once every
writeup study has results in OUT/results, else the sections of those that have
(one study alone: its own section). --report-only re-assembles OUT/REPORT.md
from OUT/results/*.json.
"""


def _not_taken(kind: str, name: str, given: dict) -> None:
    """Refuse (one line, exit 2) the first option given that a study of ``kind`` does not take."""
    for option, on in given.items():
        if on and option not in TAKES[kind]:
            who, whose = ("the writeup studies take", "their") if kind == "writeup" else (f"study {name} takes", "its")
            fail(f"{option}: {who} no {option} ({whose} options: {' '.join(TAKES[kind])})")


def register(app: typer.Typer) -> None:
    @app.command("analyze", help=_help())
    def analyze_cmd(
        study: Optional[list[str]] = typer.Argument(None, help="Study names or letters (listed above), or all.",
                                            metavar="STUDY"),
        quick: bool = typer.Option(False, "--quick", help="Small sizes (the CI run: seconds per writeup study)."),
        out: Optional[Path] = typer.Option(None, "--out", help="Output folder; default: analysis (writeup studies: "
                                           "figures/, results/, REPORT.md) or NAME (integrator studies) in "
                                           "./dicetrace-results. The committed results: "
                                           "--out analysis, --out analysis/accuracy (full runs only)."),
        res: Optional[int] = typer.Option(None, "--res", help="Writeup studies: override each study's main grid size "
                                         "(points per axis, >= 3; refused when its largest grid would not fit the "
                                         "memory available)."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Random seed of perturbations and picks, and of "
                                          "accuracy's IC sample (an integer in [0, 2**64))."),
        integrator: Optional[str] = typer.Option(None, "--integrator",
                                                 help="Writeup study l (converged): the integrator of its converged "
                                                 "models (default: each model's own). accuracy, stability: "
                                                 "comma-separated integrators (default: all)."),
        integrators_alias: IntegratorsAlias = None,
        tol: Optional[float] = typer.Option(None, "--tol", help="Writeup study l (converged): the tolerance of its "
                                            "converged models (adaptive integrators); default: each model's own."),
        window: Optional[str] = typer.Option(None, "--window", help="accuracy: window of the seed slice, a name "
                                             "(home, zoom-out, ...) or x0,x1,y0,y1 "
                                             f"(default {acc.DEFAULT_WINDOW})."),
        n: Optional[int] = typer.Option(None, "--n", help=f"accuracy: ICs in the seeded sample (default {acc.DEFAULT_N}; "
                                        f"--quick: {acc.QUICK_N}; refused when its runs would not fit the memory available)."),
        presets: Optional[str] = typer.Option(None, "--presets", help="accuracy, stability: comma-separated presets "
                                              "(default seed,physical)."),
        k_values: Optional[str] = typer.Option(None, "--k", help="stability: comma-separated stiffnesses k "
                                               "(1/s²; default 5e5 … 5e7)."),
        threads: Optional[int] = typer.Option(None, "--threads", help="accuracy: numba threads for the untimed "
                                              "reference runs (default 2; timed runs use one)."),
        device: Optional[str] = typer.Option(None, "--device", help="Writeup studies: where their batches run, cpu, "
                                             "cuda (a GPU: pip install 'dicetrace\\[cuda]') or auto (the GPU where "
                                             "there is one); default cpu. Recorded in each study's results."),
        no_cache: bool = typer.Option(False, "--no-cache", help="Writeup studies: re-simulate grids cached in OUT/cache."),
        no_report: bool = typer.Option(False, "--no-report", help="Writeup studies: do not rebuild REPORT.md."),
        report_only: bool = typer.Option(False, "--report-only", help="Only re-assemble OUT/REPORT.md from "
                                         "OUT/results/*.json (no simulation)."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="Integrator studies: no progress lines."),
    ) -> None:
        # every option is checked before anything touches the disk or computes
        integrator = either(integrator, integrators_alias)
        given = {"--quick": quick, "--out": out is not None, "--res": res is not None, "--seed": seed is not None,
                 "--integrator": integrator is not None, "--tol": tol is not None, "--window": window is not None,
                 "--n": n is not None, "--presets": presets is not None, "--k": k_values is not None,
                 "--threads": threads is not None, "--device": device is not None, "--no-cache": no_cache,
                 "--no-report": no_report, "--quiet": quiet}
        target = Path(out) if out is not None else default_out("analyze")
        if report_only:
            if study:
                fail("--report-only takes no study names")
            extra = [name for name, on in given.items() if on and name != "--out"]
            if extra:
                fail(f"{extra[0]}: --report-only runs no study, so it takes no {', '.join(extra)}")
            if not (target / "results").is_dir():
                fail(f"--out {str(target)!r} has no results/ folder to build a report from")
            print(f"wrote {build_report(target)}")
            return
        if not study:
            fail("name the studies to run (or all)")
        alone = [s for s in study if str(s).strip().lower() in INTEGRATOR_STUDIES]
        if alone:
            name = str(alone[0]).strip().lower()
            if len(study) > 1:
                fail(f"study {name} runs alone: name it without other studies")
            _not_taken(name, name, given)
            _integrator_study(name, window=window, n=n, seed=seed, quick=quick, presets=presets,
                              integrators=integrator, k_values=k_values, threads=threads, out=out, quiet=quiet)
            return
        try:
            names = resolve(study)
        except ValueError as e:
            fail(f"{e}; or one of {', '.join(INTEGRATOR_STUDIES)}, alone")
        _not_taken("writeup", "", given)
        require("analysis", "dicetrace analyze (its writeup studies)")
        options = _checked_options(names, quick=quick, res=res, seed=seed, integrator=integrator, tol=tol,
                                   device=device, no_cache=no_cache)
        why = ", ".join(w for w, on in (("--quick", quick), ("--res", res is not None),
                                        ("--seed", options.seed != DEFAULT_SEED), ("--integrator", integrator is not None),
                                        ("--tol", tol is not None)) if on)
        try:
            prepare_out(target, full=options.full, why=why)
        except ValueError as e:
            fail(f"--out: {e}")
        studies_runner.run(names, options=options, out=target, report=not no_report)


def _integrator_study(name: str, *, window, n, seed, quick, presets, integrators, k_values, threads, out,
                      quiet) -> None:
    """Run integrator study ``name`` (its options already known to be its own; each is checked there)."""
    command = command_line(f"analyze {name}")
    if name == "accuracy":
        run_accuracy(window=window, n=n, seed=seed, quick=quick, presets=presets, integrators=integrators,
                     threads=threads, out=out, quiet=quiet, command=command)
    elif name == "stability":
        run_stability(quick=quick, presets=presets, integrators=integrators, k_values=k_values, out=out, quiet=quiet,
                      command=command)
    elif name == "cuboids":
        run_cuboids(quick=quick, threads=threads, out=out, quiet=quiet, command=command)
    elif name == "bars":
        run_bars(quick=quick, threads=threads, out=out, quiet=quiet, command=command)
    elif name == "aspect":
        run_aspect(quick=quick, threads=threads, out=out, quiet=quiet, command=command)
    else:
        run_friction(quick=quick, out=out, quiet=quiet, command=command)


#: Seeds the studies' random generators take.
SEED_RANGE = (0, 2**64)


def _checked_options(names, *, quick, res, seed, integrator, tol, device, no_cache):
    """The run's :class:`~dicetrace.studies.context.Options`, each option checked (one line naming it, exit 2)."""
    if res is not None and res < 3:
        fail(f"--res must be at least 3, got {res}")
    if seed is not None and not SEED_RANGE[0] <= seed < SEED_RANGE[1]:
        fail(f"--seed must be an integer in [0, 2**64), got {seed}")
    if integrator is not None or tol is not None:
        try:  # the configuration layer checks both (a ConfigError names its field, so its option)
            with config_errors({"--integrator": integrator, "--tol": tol}):
                check_overrides(integrator, tol)
        except ValueError as e:  # what check_overrides refuses besides the configuration's checks
            given = " ".join(f"{k} {v}" for k, v in (("--integrator", integrator), ("--tol", tol)) if v is not None)
            fail(f"{given}: {e}")
    where = "cpu"
    if device is not None:
        with config_errors():  # a DeviceError: one line naming --device (cuda without a GPU)
            where = resolve_device(device)
    options = Options(quick=quick, res=res, seed=DEFAULT_SEED if seed is None else seed, no_cache=no_cache,
                      integrator=integrator, tol=tol, device=where)
    try:
        studies_runner.check_memory(names, options)
    except ValueError as e:
        fail(str(e))
    return options
