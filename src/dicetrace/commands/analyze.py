"""``dicetrace analyze``: run writeup studies of :mod:`dicetrace.studies` and rebuild their report.

Examples::

    dicetrace analyze all --quick                 # CI-sized, into ./dicetrace-results/analysis
    dicetrace analyze cells --quick --out /tmp/q  # one study
    dicetrace analyze all --out analysis          # regenerate the committed full results (repository root)
    dicetrace analyze --report-only --out analysis   # re-assemble analysis/REPORT.md only

Studies: cells (a), fractal (b), repetition (c), topology (d), damping (e),
vertices (f), settle (g), wedge (h), animation (i), or ``all``.

Output: ``--out`` (default ``./dicetrace-results/analysis``) gets
``figures/``, ``results/<study>.json``, ``cache/`` (simulated grids as plain
arrays, never unpickled; a file that is not one of them is ignored and its
grid simulated again) and ``REPORT.md``: the whole report once every study
has results there, else only the sections of the studies that have (one study
into a new folder: its own section, with its numbers and run time).  A
folder of committed results (``analysis/``, marked by
``.committed-results``) only takes full runs: ``--quick``, ``--res`` or
``--seed`` into it is refused.

Every option is checked before anything is written or computed (``--res``
>= 3 and a largest grid that fits the memory available, ``--seed`` in
[0, 2**64), a known ``--integrator``, a finite ``--tol`` in [1e-14, 1) with
which the converged models can run); a bad one is one line naming it, exit 2,
and ``--out`` is not created.

Exit codes: 0 done; 2 bad input (an option above, unknown study, unwritable
output, a CI-sized run into committed results).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from dicetrace.commands._common import fail
from dicetrace.studies import LETTERS, TITLES, resolve
from dicetrace.studies.outputs import default_out, prepare_out

#: The studies as ``analyze --help`` lists them: letter, name, what it is about.
STUDIES_HELP = "\n".join(f"  {letter}  {name:<11} {TITLES[name]}" for letter, name in LETTERS.items())


def _help() -> str:
    return f"""Run writeup studies (figures, numbers, REPORT.md) into ./dicetrace-results/analysis or --out.

Name each study by its name or its letter (the prefix of its figures,
figures/a_*.png ...), or give all:

{STUDIES_HELP}

The committed results in analysis/ are regenerated only by the full run
`dicetrace analyze all --out analysis` (from the repository root); a --quick,
--res or --seed run into analysis/ is refused. REPORT.md is the whole report
once every study has results in OUT/results, else the sections of those that
have (one study alone: its own section). --report-only re-assembles
OUT/REPORT.md from OUT/results/*.json.
"""


def register(app: typer.Typer) -> None:
    @app.command("analyze", help=_help())
    def analyze_cmd(
        study: Optional[list[str]] = typer.Argument(None, help="Study names or letters (listed above), or all.",
                                            metavar="STUDY"),
        quick: bool = typer.Option(False, "--quick", help="Small grids (the CI run: seconds per study)."),
        out: Optional[Path] = typer.Option(None, "--out", help="Output folder (figures/, results/, REPORT.md); "
                                           "default ./dicetrace-results/analysis. The committed results: --out analysis "
                                           "(full runs only)."),
        res: Optional[int] = typer.Option(None, "--res", help="Override each study's main grid size (points per axis, >= 3; refused when "
                                         "its largest grid would not fit the memory available)."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Random seed of perturbations and picks "
                                          "(an integer in [0, 2**64))."),
        integrator: Optional[str] = typer.Option(None, "--integrator", help="Integrator of the converged models "
                                                 "of study k (converged); default: each model's own."),
        tol: Optional[float] = typer.Option(None, "--tol", help="Tolerance of the converged models of study k "
                                            "(adaptive integrators); default: each model's own."),
        no_cache: bool = typer.Option(False, "--no-cache", help="Re-simulate grids cached in OUT/cache."),
        no_report: bool = typer.Option(False, "--no-report", help="Do not rebuild REPORT.md."),
        report_only: bool = typer.Option(False, "--report-only", help="Only re-assemble OUT/REPORT.md from "
                                         "OUT/results/*.json (no simulation)."),
    ) -> None:
        from dicetrace.studies.context import DEFAULT_SEED, Options

        # every option is checked before anything touches the disk or computes
        target = Path(out) if out is not None else default_out("analyze")
        if report_only:
            if study:
                fail("--report-only takes no study names")
            given = [name for name, on in (("--quick", quick), ("--res", res is not None), ("--seed", seed is not None),
                                           ("--integrator", integrator is not None), ("--tol", tol is not None),
                                           ("--no-cache", no_cache), ("--no-report", no_report)) if on]
            if given:
                fail(f"{given[0]}: --report-only runs no study, so it takes no {', '.join(given)}")
            if not (target / "results").is_dir():
                fail(f"--out {str(target)!r} has no results/ folder to build a report from")
            from dicetrace.studies.report import build

            print(f"wrote {build(target)}")
            return
        if not study:
            fail("name the studies to run (or all)")
        try:
            names = resolve(study)
        except ValueError as e:
            fail(str(e))
        options = _checked_options(names, quick=quick, res=res, seed=seed, integrator=integrator, tol=tol,
                                   no_cache=no_cache)
        why = ", ".join(w for w, on in (("--quick", quick), ("--res", res is not None),
                                        ("--seed", options.seed != DEFAULT_SEED), ("--integrator", integrator is not None),
                                        ("--tol", tol is not None)) if on)
        try:
            prepare_out(target, full=options.full, why=why)
        except ValueError as e:
            fail(f"--out: {e}")
        from dicetrace.studies.runner import run

        run(names, options=options, out=target, report=not no_report)


#: Seeds the studies' random generators take.
SEED_RANGE = (0, 2**64)


def _checked_options(names, *, quick, res, seed, integrator, tol, no_cache):
    """The run's :class:`~dicetrace.studies.context.Options`, each option checked (one line naming it, exit 2)."""
    import math

    from dicetrace.params import INTEGRATORS, TOL_MIN
    from dicetrace.studies.context import DEFAULT_SEED, Options

    if res is not None and res < 3:
        fail(f"--res must be at least 3, got {res}")
    if seed is not None and not SEED_RANGE[0] <= seed < SEED_RANGE[1]:
        fail(f"--seed must be an integer in [0, 2**64), got {seed}")
    if integrator is not None and integrator not in INTEGRATORS:
        fail(f"--integrator: unknown integrator {integrator!r} (choose from {', '.join(INTEGRATORS)})")
    if tol is not None and not (math.isfinite(tol) and TOL_MIN <= tol < 1):
        fail(f"--tol must be a number in [{TOL_MIN:g}, 1), got {tol}")
    if integrator is not None or tol is not None:
        from dicetrace.studies.study_converged import check_overrides

        try:
            check_overrides(integrator, tol)
        except ValueError as e:
            given = " ".join(f"{k} {v}" for k, v in (("--integrator", integrator), ("--tol", tol)) if v is not None)
            fail(f"{given}: {e}")
    options = Options(quick=quick, res=res, seed=DEFAULT_SEED if seed is None else seed, no_cache=no_cache,
                      integrator=integrator, tol=tol)
    from dicetrace.studies.runner import check_memory

    try:
        check_memory(names, options)
    except ValueError as e:
        fail(str(e))
    return options
