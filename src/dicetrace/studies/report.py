"""Assembling ``REPORT.md`` from the report template (package data) and the studies' ``results/*.json``.

Placeholders in the template (``dicetrace/studies/REPORT.template.md``):

``{{v:STUDY.path.to.value|FMT}}``
    A number (or text) from ``results/STUDY.json``; the path walks dict keys
    and list indices; ``FMT`` is a Python format spec (``.3f``, ``d``, ``.2e``),
    or ``%`` for a percentage with one decimal.
``{{t:STUDY.NAME}}``
    The markdown table ``tables[NAME]`` of that study.
``{{f:STUDY.KEY}}``
    The figure ``figures[KEY]``: an image link relative to the report, and
    its caption in italics.

A placeholder whose value is missing renders as ``n/a`` (and is listed on
stderr). When any study ran with ``--quick`` the report starts with a
warning that its numbers come from CI-sized grids.
"""

from __future__ import annotations

import json
import math
import re
import sys
from importlib import resources
from pathlib import Path

_PH = re.compile(r"\{\{([vtf]):([^}|]+)(?:\|([^}]*))?\}\}")
QUICK_WARNING = ("> **Quick run.** These numbers come from the CI-sized grids of `dicetrace analyze --quick`; they "
                 "only show that the pipeline works and do not support the text's conclusions. The committed "
                 "`analysis/REPORT.md` comes from the full run.\n\n")


def template_text() -> str:
    """The report template shipped with the package."""
    return resources.files("dicetrace.studies").joinpath("REPORT.template.md").read_text(encoding="utf-8")


def _walk(obj, path: list[str]):
    for key in path:
        obj = obj[int(key)] if isinstance(obj, list) else obj[key]
    return obj


def _fmt(v, spec: str | None) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    if spec == "%":
        return f"{100 * v:.1f} %"
    if spec:
        try:
            return format(v, spec)
        except (TypeError, ValueError):
            return str(v)
    return str(v)


def render(template: str, results: dict[str, dict]) -> tuple[str, list[str]]:
    """The template with its placeholders filled from ``results`` (study -> JSON), and the missing ones."""
    missing: list[str] = []

    def sub(m: re.Match) -> str:
        kind, ref, spec = m.group(1), m.group(2).strip(), m.group(3)
        study, _, rest = ref.partition(".")
        res = results.get(study)
        try:
            if res is None:
                raise KeyError(study)
            if kind == "v":
                return _fmt(_walk(res, rest.split(".")), spec)
            if kind == "t":
                return res["tables"][rest]
            fig = res["figures"][rest]
            return f"![{rest}]({fig['path']})\n\n*{fig.get('caption', '')}*"
        except (KeyError, IndexError, ValueError, TypeError):
            missing.append(m.group(0))
            return "n/a"

    return _PH.sub(sub, template), missing


def build(out: Path, template: str | None = None) -> Path:
    """Write ``OUT/REPORT.md`` from ``OUT/results/*.json``; returns its path."""
    out = Path(out)
    results = {}
    for p in sorted((out / "results").glob("*.json")):
        try:
            results[p.stem] = json.loads(p.read_text())
        except ValueError:
            print(f"report: cannot read {p}", file=sys.stderr)
    text, missing = render(template if template is not None else template_text(), results)
    if any(r.get("quick") for r in results.values()):
        text = QUICK_WARNING + text
    path = out / "REPORT.md"
    path.write_text(text)
    if missing:
        print(f"report: {len(missing)} placeholder(s) without a value, e.g. {missing[:3]}", file=sys.stderr)
    return path
