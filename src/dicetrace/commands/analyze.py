"""``dicetrace analyze``: run writeup studies of :mod:`dicetrace.studies` and rebuild their report.

Examples::

    dicetrace analyze all --quick                 # CI-sized, into ./dicetrace-results/analysis
    dicetrace analyze cells --quick --out /tmp/q  # one study
    dicetrace analyze all --out analysis          # regenerate the committed full results (repository root)
    dicetrace analyze --report-only --out analysis   # re-assemble analysis/REPORT.md only

Studies: cells (a), fractal (b), repetition (c), topology (d), damping (e),
vertices (f), settle (g), wedge (h), animation (i), or ``all``.

Output: ``--out`` (default ``./dicetrace-results/analysis``) gets
``figures/``, ``results/<study>.json``, ``cache/`` and ``REPORT.md``.  A
folder of committed results (``analysis/``, marked by
``.committed-results``) only takes full runs: ``--quick``, ``--res`` or
``--seed`` into it is refused.

Exit codes: 0 done; 2 bad input (unknown study, unwritable output, a
CI-sized run into committed results).
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
--res or --seed run into analysis/ is refused. --report-only re-assembles
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
        res: Optional[int] = typer.Option(None, "--res", help="Override each study's main grid size (points per axis)."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Random seed of perturbations and picks."),
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

        target = Path(out) if out is not None else default_out("analyze")
        if report_only:
            if study:
                fail("--report-only takes no study names")
            if not (target / "results").is_dir():
                fail(f"{str(target)!r} has no results/ folder to build a report from")
            from dicetrace.studies.report import build

            print(f"wrote {build(target)}")
            return
        if not study:
            fail("name the studies to run (or all)")
        try:
            names = resolve(study)
        except ValueError as e:
            fail(str(e))
        if res is not None and res < 3:
            fail(f"--res must be at least 3, got {res}")
        options = Options(quick=quick, res=res, seed=DEFAULT_SEED if seed is None else seed, no_cache=no_cache,
                          integrator=integrator, tol=tol)
        why = ", ".join(w for w, on in (("--quick", quick), ("--res", res is not None),
                                        ("--seed", options.seed != DEFAULT_SEED), ("--integrator", integrator is not None),
                                        ("--tol", tol is not None)) if on)
        try:
            prepare_out(target, full=options.full, why=why)
        except ValueError as e:
            fail(str(e))
        from dicetrace.studies.runner import run

        run(names, options=options, out=target, report=not no_report)
