"""Assembling ``REPORT.md`` from the report template (package data) and the studies' ``results/*.json``.

Placeholders in the template (``dicetrace/studies/REPORT.template.md``):

``{{v:STUDY.path.to.value|FMT}}``
    A number (or text) from ``results/STUDY.json``; the path walks dict keys
    and list indices; ``FMT`` is a Python format spec (``.3f``, ``d``, ``.2e``),
    or ``%`` for a percentage with one decimal.
``{{t:STUDY.NAME}}``, ``{{t:STUDY.NAME|drop=TEXT;TEXT}}``
    The markdown table ``tables[NAME]`` of that study; with ``drop=``, without
    the columns whose header is one of the TEXTs and the rows whose first cell
    is one (a verdict or a withdrawn statistic the study's own table still
    carries; the report states those in its own words).
``{{f:STUDY.KEY}}``
    The figure ``figures[KEY]``: an image link relative to the report, and
    its caption in italics.
``{{s:STUDY.NAME}}``
    A sentence that compares numbers, written from them when the report is
    assembled: ``SENTENCES[NAME](results)`` of the study's module (so
    "higher" is said only where the numbers are higher, whatever run they
    come from).

A placeholder whose value is missing renders as ``n/a`` (and is listed on
stderr). When any study ran with ``--quick`` the report starts with a
warning that its numbers come from CI-sized grids.

Two studies run alone into folders of their own beside ``results/``
(:data:`FOLDER_STUDIES`: ``OUT/cuboids/results.json``, ``OUT/bars/results.json``,
``OUT/aspect/results.json``) have
sections of the whole report too; a section that quotes one of them is left out
while its results are not there.

The whole report needs the results of every writeup study.  While some are
missing (``dicetrace analyze settle`` into a new folder), ``REPORT.md`` holds
only the sections (``## g. ...``) of the studies whose results are there,
under a header that says so and gives each one's own run time: a paragraph
that quotes a study without results (a cross-reference, the full run's
timings) is left out, never shown as ``n/a``.
"""

from __future__ import annotations

import json
import math
import re
import sys
from importlib import resources
from pathlib import Path

from dicetrace.studies.outputs import write_text

#: Studies run alone (``dicetrace analyze NAME --out OUT/NAME``) whose ``OUT/NAME/results.json`` the report quotes.
FOLDER_STUDIES = ("cuboids", "bars", "aspect")
_PH = re.compile(r"\{\{([vtfs]):([^}|]+)(?:\|([^}]*))?\}\}")
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


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def drop_from_table(table: str, spec: str | None) -> str:
    """``table`` (Markdown) without the columns headed by, and the rows starting with, a text of ``spec``
    (``drop=A;B``); the table itself when ``spec`` names nothing to drop."""
    if not spec or not spec.startswith("drop="):
        return table
    names = {t.strip() for t in spec[len("drop="):].split(";") if t.strip()}
    lines = table.splitlines()
    if len(lines) < 2 or not lines[0].lstrip().startswith("|"):
        return table
    keep = [i for i, h in enumerate(_cells(lines[0])) if h not in names]
    out = []
    for n, line in enumerate(lines):
        if not line.lstrip().startswith("|"):
            out.append(line)
            continue
        cells = _cells(line)
        if n >= 2 and cells and cells[0] in names:
            continue
        out.append("| " + " | ".join(cells[i] for i in keep if i < len(cells)) + " |" if n != 1
                   else "|" + "|".join("---" for _ in keep) + "|")
    return "\n".join(out)


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
                return drop_from_table(res["tables"][rest], spec)
            if kind == "s":
                from dicetrace.studies import study_module

                return study_module(study).SENTENCES[rest](res)
            fig = res["figures"][rest]
            return f"![{rest}]({fig['path']})\n\n*{fig.get('caption', '')}*"
        except (KeyError, IndexError, ValueError, TypeError):
            missing.append(m.group(0))
            return "n/a"

    return _PH.sub(sub, template), missing


#: A level-2 heading of the template; a study's section is ``## <letter>. ...`` up to the next one.
_H2 = re.compile(r"^## ", re.M)
_STUDY_H2 = re.compile(r"## ([a-z])\. ")


def sections(template: str) -> dict[str, str]:
    """The template's section of each writeup study (study name -> its text, from its ``## x.`` heading to the
    next level-2 heading, without the trailing ``---``)."""
    from dicetrace.studies import LETTERS

    starts = [m.start() for m in _H2.finditer(template)] + [len(template)]
    out = {}
    for a, b in zip(starts[:-1], starts[1:]):
        m = _STUDY_H2.match(template, a)
        if m and m.group(1) in LETTERS:
            text = template[a:b].rstrip()
            while text.endswith("---"):
                text = text[:-3].rstrip()
            out[LETTERS[m.group(1)]] = text + "\n"
    return out


def titled_section(heading: str, template: str | None = None) -> str:
    """The template's level-2 section whose heading starts with ``heading`` (``"Real dice I"``), up to the next one
    (ValueError when there is none)."""
    text = template_text() if template is None else template
    start = text.find(f"\n## {heading}")
    if start < 0:
        raise ValueError(f"no section headed {heading!r} in the report template")
    end = text.find("\n## ", start + 4)
    return text[start + 1:end if end >= 0 else len(text)]


def _studies_quoted(text: str) -> set[str]:
    return {m.group(2).strip().partition(".")[0] for m in _PH.finditer(text)}


def _keep_paragraphs(text: str, have: set[str]) -> str:
    """``text`` without the paragraphs that quote a study not in ``have``."""
    paragraphs = re.split(r"\n[ \t]*\n", text.strip("\n"))
    return "\n\n".join(p for p in paragraphs if _studies_quoted(p) <= have) + "\n"


def partial_template(template: str, studies: list[str], results: dict[str, dict]) -> str:
    """A report template of the sections of ``studies`` only: a header naming them, with each one's run time
    (its results' ``wall_s``), the template's conventions, then their sections; paragraphs that quote another
    study are left out."""
    from dicetrace.studies import LETTERS, WRITEUP_STUDIES

    letter = {name: lt for lt, name in LETTERS.items()}
    ran = ", ".join(f"{letter[s]} ({s}, {_fmt(results.get(s, {}).get('wall_s'), '.0f')} s)" for s in studies)
    head = [
        "# The chaos of the 2019 die, measured: " + ("section " if len(studies) == 1 else "sections ")
        + ", ".join(letter[s] for s in studies),
        "",
        f"Only part of the report: the results of {len(studies)} of the {len(WRITEUP_STUDIES)} writeup studies are "
        f"in `results/` ({ran}). Paragraphs that quote a study not run here are left out; "
        "`dicetrace analyze all` runs every study and writes the whole report.",
        "",
    ]
    conventions = [p for p in re.split(r"\n[ \t]*\n", template) if p.startswith("**Conventions.**")]
    body = [_keep_paragraphs(sec, set(studies)) for name, sec in sections(template).items() if name in studies]
    return "\n".join(head) + "\n" + "".join(c + "\n\n" for c in conventions) + "\n".join(body)


def _without_sections_of(template: str, missing: set[str]) -> str:
    """``template`` without the level-2 sections that quote a study of ``missing``."""
    starts = [m.start() for m in _H2.finditer(template)] + [len(template)]
    head = template[:starts[0]]
    keep = [template[a:b] for a, b in zip(starts[:-1], starts[1:]) if not (_studies_quoted(template[a:b]) & missing)]
    return head + "".join(keep)


def build(out: Path, template: str | None = None) -> Path:
    """Write ``OUT/REPORT.md`` from ``OUT/results/*.json``: the whole report when every writeup study has results
    there, else the sections of those that have (:func:`partial_template`); returns its path."""
    from dicetrace.studies import WRITEUP_STUDIES

    out = Path(out)
    results = {}
    for p in sorted((out / "results").glob("*.json")):
        if p.name.startswith("."):  # a temporary file a killed run left (outputs.written): no study's results
            continue
        try:
            results[p.stem] = json.loads(p.read_text())
        except ValueError:
            print(f"report: cannot read {p}", file=sys.stderr)
    for name in FOLDER_STUDIES:
        p = out / name / "results.json"
        if p.is_file():
            try:
                results[name] = json.loads(p.read_text())
            except ValueError:
                print(f"report: cannot read {p}", file=sys.stderr)
    template = template if template is not None else template_text()
    template = _without_sections_of(template, {s for s in FOLDER_STUDIES if s not in results})
    have = [s for s in WRITEUP_STUDIES if s in results]
    if len(have) < len(WRITEUP_STUDIES):
        template = partial_template(template, have, results)
    text, missing = render(template, results)
    if any(results[s].get("quick") for s in have) or (len(have) == len(WRITEUP_STUDIES)
                                                     and any(r.get("quick") for r in results.values())):
        text = QUICK_WARNING + text
    path = write_text(out / "REPORT.md", text, "report")
    if missing:
        print(f"report: {len(missing)} placeholder(s) without a value, e.g. {missing[:3]}", file=sys.stderr)
    return path
