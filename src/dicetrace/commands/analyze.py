"""``dicetrace analyze``: run a study of ``analysis/`` (or all of them) and rebuild its report.

Examples::

    dicetrace analyze cells --quick --out /tmp/quick     # one study, CI-sized grids
    dicetrace analyze settle                             # full size, into analysis/
    dicetrace analyze all                                # every study, then REPORT.md

Studies: cells (a), fractal (b), repetition (c), topology (d), damping (e),
vertices (f), settle (g), wedge (h), animation (i), or ``all``.

The study scripts live in the repository's ``analysis/`` folder, not in the
installed package; the command finds that folder from ``--studies-dir``,
``$DICETRACE_STUDIES``, the current directory or its parents, or the source
checkout this package was installed from (editable installs).

Exit codes: 0 done; 2 bad input (unknown study, no analysis folder,
unwritable output).
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from typing import Optional

import typer

from dicetrace.commands._common import fail

STUDY_NAMES = ("cells", "fractal", "repetition", "topology", "damping", "vertices", "settle", "wedge", "animation")
LETTERS = dict(zip("abcdefghi", STUDY_NAMES))


def find_studies_dir(explicit: Optional[Path] = None) -> Path:
    """The folder holding ``run_all.py`` (see the module docstring for the search order)."""
    cands: list[Path] = []
    if explicit is not None:
        cands.append(Path(explicit))
    env = os.environ.get("DICETRACE_STUDIES")
    if env:
        cands.append(Path(env))
    here = Path.cwd().resolve()
    for d in (here, *here.parents):
        cands.append(d / "analysis")
        if d.name == "analysis":
            cands.append(d)
    import dicetrace

    pkg = Path(dicetrace.__file__).resolve()
    if len(pkg.parents) > 2:
        cands.append(pkg.parents[2] / "analysis")  # src/dicetrace/__init__.py -> repo/analysis
    for c in cands:
        if (c / "run_all.py").is_file():
            return c
    if explicit is not None:
        fail(f"--studies-dir {str(explicit)!r} holds no run_all.py")
    fail("cannot find the analysis/ folder with run_all.py: run from the repository, "
         "or pass --studies-dir (or set DICETRACE_STUDIES)")
    raise AssertionError  # unreachable


def _load_run_all(folder: Path):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
    spec = importlib.util.spec_from_file_location("dicetrace_studies_run_all", folder / "run_all.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def resolve_studies(names: list[str]) -> list[str]:
    out: list[str] = []
    for n in names:
        key = n.strip().lower()
        if key == "all":
            return list(STUDY_NAMES)
        key = LETTERS.get(key, key)
        if key not in STUDY_NAMES:
            fail(f"unknown study {n!r} (choose from all, {', '.join(STUDY_NAMES)}, or a..i)")
        if key not in out:
            out.append(key)
    return out


def register(app: typer.Typer) -> None:
    @app.command("analyze")
    def analyze_cmd(
        study: list[str] = typer.Argument(..., help="Study name(s): " + ", ".join(STUDY_NAMES) + ", a..i, or all."),
        quick: bool = typer.Option(False, "--quick", help="Small grids (the CI run: seconds per study)."),
        out: Optional[Path] = typer.Option(None, "--out", help="Output folder (figures/, results/, REPORT.md); "
                                           "default: the analysis/ folder itself."),
        res: Optional[int] = typer.Option(None, "--res", help="Override each study's main grid size (points per axis)."),
        seed: Optional[int] = typer.Option(None, "--seed", help="Random seed of perturbations and picks."),
        no_cache: bool = typer.Option(False, "--no-cache", help="Re-simulate grids cached in OUT/cache."),
        no_report: bool = typer.Option(False, "--no-report", help="Do not rebuild REPORT.md."),
        studies_dir: Optional[Path] = typer.Option(None, "--studies-dir", help="The repository's analysis/ folder."),
    ) -> None:
        """Run analysis studies (figures, numbers, REPORT.md) against the simulator."""
        names = resolve_studies(study)
        if res is not None and res < 3:
            fail(f"--res must be at least 3, got {res}")
        folder = find_studies_dir(studies_dir)
        target = Path(out) if out is not None else folder
        try:
            target.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            fail(f"cannot create output folder {str(target)!r}: {e.strerror}")
        if not os.access(target, os.W_OK):
            fail(f"output folder {str(target)!r} is not writable")
        run_all = _load_run_all(folder)
        run_all.run(names, quick=quick, out=target, res=res, seed=seed, no_cache=no_cache, report=not no_report)
