"""Assemble ``REPORT.md`` from ``REPORT.template.md`` and the studies' ``results/*.json``.

Placeholders in the template:

``{{v:STUDY.path.to.value|FMT}}``
    A number (or text) from ``results/STUDY.json``; the path walks dict keys
    and list indices; ``FMT`` is a Python format spec (``.3f``, ``d``, ``.2e``).
``{{t:STUDY.NAME}}``
    The markdown table ``tables[NAME]`` of that study.
``{{f:STUDY.KEY}}``
    The figure ``figures[KEY]``: an image link relative to the report, and
    its caption in italics.

A placeholder whose value is missing renders as ``n/a`` (and is listed on
stderr). When any study ran with ``--quick`` the report starts with a
warning that its numbers come from CI-sized grids.

    python analysis/report.py [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TEMPLATE = HERE / "REPORT.template.md"
_PH = re.compile(r"\{\{([vtf]):([^}|]+)(?:\|([^}]*))?\}\}")


def _walk(obj, path: list[str]):
    for key in path:
        if isinstance(obj, list):
            obj = obj[int(key)]
        else:
            obj = obj[key]
    return obj


def _fmt(v, spec: str | None) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    if spec:
        if spec == "%":  # percentage with one decimal
            return f"{100 * v:.1f} %"
        try:
            return format(v, spec)
        except (TypeError, ValueError):
            return str(v)
    return str(v)


def render(template: str, results: dict[str, dict]) -> tuple[str, list[str]]:
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
            cap = fig.get("caption", "")
            return f"![{rest}]({fig['path']})\n\n*{cap}*"
        except (KeyError, IndexError, ValueError, TypeError):
            missing.append(m.group(0))
            return "n/a"

    return _PH.sub(sub, template), missing


def build(out: Path, template: Path = TEMPLATE) -> Path:
    out = Path(out)
    results = {}
    for p in sorted((out / "results").glob("*.json")):
        try:
            results[p.stem] = json.loads(p.read_text())
        except ValueError:
            print(f"report: cannot read {p}", file=sys.stderr)
    text, missing = render(Path(template).read_text(), results)
    if any(r.get("quick") for r in results.values()):
        text = ("> **Quick run.** These numbers come from the CI-sized grids of `run_all.py --quick`; they only "
                "show that the pipeline works and do not support the text's conclusions. The committed "
                "`analysis/REPORT.md` comes from the full run.\n\n") + text
    path = out / "REPORT.md"
    path.write_text(text)
    if missing:
        print(f"report: {len(missing)} placeholder(s) without a value, e.g. {missing[:3]}", file=sys.stderr)
    return path


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description="Assemble REPORT.md from results/*.json")
    ap.add_argument("--out", type=Path, default=HERE)
    a = ap.parse_args(argv)
    print(build(a.out))


if __name__ == "__main__":
    main(sys.argv[1:])
