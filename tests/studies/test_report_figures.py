"""Every figure README.md, ``analysis/REPORT.md`` and ``analysis/accuracy/README.md`` quote is held by a committed
results file.

A *figure* is a number in the prose or tables of the two documents (code blocks, inline code, link targets
and image paths are not prose). A results file is one a study or a benchmark wrote: ``analysis/results/*``
(JSON and CSV), the integrator studies' ``analysis/accuracy/*.csv``, ``*.json`` and their written summaries
(``summary.md``, ``stability.md``, ``v_reg.md``), the cuboid study's ``analysis/cuboids/`` (``results.json``,
``cuboids.csv``, ``cuboids.md``), the bar and aspect studies' ``analysis/bars/`` and ``analysis/aspect/`` (their
``results.json``, CSV and summary), and ``benchmarks/results/**`` where one is committed.
Hand-written pages (``analysis/README.md``, ``analysis/accuracy/README.md``, ``TUNING.md``) are not sources.

A figure is held when some number in those files, rounded to the figure's printed precision, is the figure
(``23.28`` holds ``23.28``; ``0.416`` holds ``41.6 %``; ``1.07e-08`` holds ``1.1e-08``; signs are ignored).
This is a necessary condition, not a sufficient one: the files hold thousands of numbers, so a figure of one
or two significant digits is often held by chance; what the test does catch is a figure of three or more
digits (a timing, a rate, a count) that no study wrote. The exceptions below are the figures that are not
measurements, each with its reason and, where it can be, a check that the reason is true.

Further: withdrawn claims appear only in the section that withdraws them, and every figure of the README's
paragraph of answers ("The report answers ...") appears in REPORT.md as printed there.
"""

from __future__ import annotations

import bisect
import json
import math
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
REPORT = REPO / "analysis" / "REPORT.md"
ACCURACY = REPO / "analysis" / "accuracy" / "README.md"

_SUP = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-")
#: A number as printed: 23.28, 15,750 or 17 000 (thousands), 1.2e-05, 5·10⁻⁸ (the ·10 must carry an exponent).
NUMBER = re.compile(r"(?<![\w.·⁰¹²³⁴⁵⁶⁷⁸⁹/#])(?:\d{1,3}(?:,\d{3})+(?![\d.])|\d{1,3}(?: \d{3})+(?![\d.,])|\d+(?:\.\d+)?)"
                    r"(?:e[+-]?\d+|·10⁻?[⁰¹²³⁴⁵⁶⁷⁸⁹]+)?(?![\w.]\d|\w)")


def _scan_source():
    from dicetrace.scan import map_rrd

    return map_rrd.MAX_LABELLED


#: Figures that are not measurements: literal -> (reason, a check of the reason or None).
EXCEPTIONS: dict[str, tuple[str, object]] = {
    "2019": ("the year of the writeup and its program", None),
    "2016": ("a citation year (Daza et al. 2016)", None),
    "2021": ("a citation year (Puy et al. 2021)", None),
    "2003": ("a citation year (Celledoni, Marthinsen & Owren 2003)", None),
    "2013": ("a citation year (Motter, Gruiz, Károlyi & Tél 2013)", None),
    "2017": ("a citation year (Chen, Nishikawa & Motter 2017)", None),
    "3.51": ("Tsit5's real-axis stability reach, a property of its coefficients; tests/core/test_integrators.py",
             "tests/core/test_integrators.py"),
    # the seed 3-D slice's z direction, an input of section c's stacks (docs/model.md §11)
    "4.5669": ("a coordinate of the seed 3-D slice's z direction (an input)", None),
    "3.1618": ("a coordinate of the seed 3-D slice's z direction (an input)", None),
    "0.4877": ("a coordinate of the seed 3-D slice's z direction (an input)", None),
    "1.3925": ("a coordinate of the seed 3-D slice's z direction (an input)", None),
    "2.7344": ("a coordinate of the seed 3-D slice's z direction (an input)", None),
    "4.7875": ("a coordinate of the seed 3-D slice's z direction (an input)", None),
    # README facts that tests, not studies, establish
    "1.3·10⁻¹²": ("README's check table: tests/core/test_reference.py asserts it", "tests/core/test_reference.py"),
    "1674": ("README's check table: the steps of a reference trace, tests/core/test_reference.py", "tests/core/test_reference.py"),
    "40,000": ("a code constant: scan.map_rrd.MAX_LABELLED", _scan_source),
}


def _parse(token: str) -> tuple[float, str, float]:
    """The value of a printed number, and its precision: ('abs', half a unit of its last digit) or
    ('rel', the same relative to its mantissa) for a number in scientific notation."""
    t = token.replace(",", "").replace(" ", "")
    if "·10" in t:
        mant, exp = t.split("·10")
        dec = len(mant.partition(".")[2])
        return float(mant) * 10 ** int(exp.translate(_SUP)), "rel", 0.5 * 10 ** -dec / float(mant)
    if "e" in t:
        mant = t.split("e")[0]
        dec = len(mant.partition(".")[2])
        return float(t), "rel", (0.5 * 10 ** -dec / float(mant)) if float(mant) else 0.0
    return float(t), "abs", 0.5 * 10 ** -len(t.partition(".")[2])


def _numbers_in(text: str, out: list[float]) -> None:
    for m in NUMBER.finditer(text):
        out.append(abs(_parse(m.group(0))[0]))


def _walk(obj, out: list[float]) -> None:
    if isinstance(obj, dict):
        for v in obj.values():
            _walk(v, out)
    elif isinstance(obj, list):
        for v in obj:
            _walk(v, out)
    elif isinstance(obj, bool):
        return
    elif isinstance(obj, (int, float)):
        if math.isfinite(obj):
            out.append(abs(float(obj)))
    elif isinstance(obj, str):
        _numbers_in(obj, out)


def result_files() -> list[Path]:
    acc = REPO / "analysis" / "accuracy"
    files = [*sorted((REPO / "analysis" / "results").glob("*.json")), *sorted((REPO / "analysis" / "results").glob("*.csv")),
             *sorted(acc.glob("*.csv")), *sorted(acc.glob("*.json")),
             *(acc / n for n in ("summary.md", "stability.md", "v_reg.md") if (acc / n).exists()),
             *(REPO / "analysis" / "cuboids" / n for n in ("results.json", "cuboids.csv", "cuboids.md")
               if (REPO / "analysis" / "cuboids" / n).exists()),
             *(REPO / "analysis" / d / n for d, names in (("bars", ("results.json", "bars.csv", "bars.md")),
                                                          ("aspect", ("results.json", "aspect.csv", "aspect.md")))
               for n in names if (REPO / "analysis" / d / n).exists()),
             *sorted(p for p in (REPO / "benchmarks" / "results").rglob("*") if p.is_file())]
    return files


def held_values() -> list[float]:
    out: list[float] = []
    for f in result_files():
        if f.suffix == ".json":
            _walk(json.loads(f.read_text()), out)
        elif f.suffix in (".csv", ".md", ".txt"):
            _numbers_in(f.read_text(), out)
    return sorted(set(out))


def is_held(token: str, values: list[float]) -> bool:
    x, kind, tol = _parse(token)
    x = abs(x)
    for target, scale in ((x, 1.0), (x / 100, 0.01)):  # the number itself, or a percentage of a fraction
        half = tol * scale if kind == "abs" else tol * target
        lo, hi = target - half * (1 + 1e-9) - 1e-15, target + half * (1 + 1e-9) + 1e-15
        i = bisect.bisect_left(values, lo)
        if i < len(values) and values[i] <= hi:
            return True
    return False


def prose(text: str) -> str:
    """``text`` without code blocks, inline code, and link or image targets (paths and URLs)."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = re.sub(r"`(?:[^`\n]|\n(?![ \t]*\n))+`", "", text)  # inline code may wrap, not span paragraphs
    return re.sub(r"(!?\[[^\]]*\])\([^)]*\)", r"\1", text)


#: References to sections, not figures: "writeup 4.1–4.2", "(5.1, 5.7)" in the answers table, "§5.5", "issue 11".
_REFERENCE = re.compile(r"(?:writeup|appendix|§|issue|sections?)\s*§?\s*[\d.]+(?:\s*(?:[–,-]|and)\s*[\d.]+)*"
                        r"|^\| [^|]*\(([\d.]+(?:, [\d.]+)*|issue \d+)\) \|", re.M)


def figures(text: str) -> list[tuple[str, str]]:
    """(figure, its line) of every figure in the prose of ``text``, references to sections left out."""
    out = []
    for line in prose(text).splitlines():
        clean = _REFERENCE.sub(" ", line)
        out += [(m.group(0), line.strip()) for m in NUMBER.finditer(clean)]
    return out


@pytest.fixture(scope="module")
def values():
    return held_values()


def test_the_matcher_tells_held_from_not_held():
    vals = sorted({23.275959068295453, 0.41584, 1.0712e-08, 15750.0})
    assert is_held("23.28", vals) and is_held("23.3", vals) and not is_held("23.27", vals)
    assert is_held("41.6", vals) and is_held("1.1e-08", vals) and is_held("15,750", vals) and is_held("15 750", vals)
    assert not is_held("15,751", vals) and not is_held("2.3e-08", vals)
    assert [f for f, _ in figures("λ = 23.28 ± 0.86 /s (writeup 4.1–4.2) `cmd --res 401` [a](b/c_1.png) 5·10⁻⁸")] \
        == ["23.28", "0.86", "5·10⁻⁸"]


def test_the_exceptions_are_true():
    for literal, (reason, check) in EXCEPTIONS.items():
        assert reason
        if callable(check):
            assert _parse(literal)[0] == check(), literal
        elif isinstance(check, str):
            assert (REPO / check).exists(), check


@pytest.mark.skipif(not REPORT.exists(), reason="no committed report here")
@pytest.mark.parametrize("doc", [README, REPORT, ACCURACY], ids=["README.md", "REPORT.md", "accuracy-README.md"])
def test_every_figure_is_held_by_a_results_file(doc, values):
    unheld = [(f, line) for f, line in figures(doc.read_text()) if f not in EXCEPTIONS and not is_held(f, values)]
    assert not unheld, "figures no results file holds:\n" + "\n".join(f"  {f!r} in: {line[:160]}" for f, line in unheld)


#: Claims section k (or j) withdraws: a pattern, and the one section allowed to quote it.
WITHDRAWN = [
    # the withdrawn rate, as it was claimed (with its unit): section g's table of medians over every side may
    # print the same digits for another statistic (the seed-substep run's median, 23.7 ± 0.2, since 40e4a78)
    (r"23\.7 ± 0\.2 ?/s", "### k4."),
    (r"15,?750", "### k6."),
    (r"0\.5–0\.9", "### k1."),
    (r"no vertex survives", None),
    (r"to 3–4 %", None),
    (r"κ/λ[^|\n]{0,40}1\.14|1\.14 ± 0\.01", None),
    (r"so every disagreement is numerical", "### k2."),
    (r"not chaotic at that scale", "### k2."),
    # issue 44: the border rate of one fit range (section o quotes it once, as what it was)
    (r"22\.95 ± 0\.06", "## o."),
    # issue 44: the seed edge release as a bound, and the edge test on the commit clock
    (r"27\.3 ± 1\.6 vs 22\.66", None),
    (r"so the final saddle is not shown to be the edge balance", None),
    (r"inconsistent \(z = -11\.1\)", None),
    # issue 44: the triple point's bisection box read as its location, and a refutation of the 6-D statement
    (r"\| located to \|", None),
    (r"closed on a point \(to 1e-11\)", None),
    (r"no vertex in IC⁶\) is refuted", None),
    (r"IC space has no vertices is refuted", None),
    # issue 44: doubly transient "in every model", a rise "through the whole tail", a saddle bound on λ₁
    (r"doubly transient \(supported, in every model\)", None),
    (r"rises through the whole tail", None),
    (r"rises from 17\.1 to 27\.3", None),
    (r"which no saddle with one\s+unstable direction allows", None),
    (r"ε_c ≈ [\d.e-]+ \(± [\d.]+ dex, at the floor's edge\)", None),
    # issue 44: the join fraction of grid paths as a lower bound, and sequences below the 0.99 rule as an answer
    (r"\*\*Fewer cells than regions\*\*", None),
    (r"a path in a stack is (?:one|a path) in IC space", None),
    (r"\*\*No\*\* \(physical, contact-tsit5", None),
    # issue 44: the sweep's commit hazard called a settling hazard, counted over unconverged conditions
    (r"settling hazard", None),
    (r"in 14 of\s+15 \(z > 2\)", None),
    # issue 44: section l's all-range λ rows with a verdict
    (r"settle-time divergence λ, all sides \(1/s\) \|[^\n]*\*\*changed\*\*", None),
    # the cuboids' verdict said not to rest on the binomial errors, from a test that takes the data's estimated φ as
    # known (the quasi-binomial F test, study_cuboids.nested_quasi_p, lets the gentle throws pass at every degree)
    (r"does\s+not\s+rest\s+on\s+(?:that|the\s+binomial)\s+error\s+model", None),
    (r"every\s+throw\s+model\s+still\s+fails", None),
    # section s: the located points' share called a lower bound (it is scaled up and extrapolated beyond the fits)
    (r"It\s+is\s+a\s+lower\s+bound:\s+only\s+triple\s+points", None),
]


def _section_of(text: str, pos: int) -> str:
    heads = [m for m in re.finditer(r"^#{2,3} .*$", text[:pos], re.M)]
    return heads[-1].group(0) if heads else ""


@pytest.mark.skipif(not REPORT.exists(), reason="no committed report here")
def test_withdrawn_claims_appear_only_where_they_are_withdrawn():
    report, readme = REPORT.read_text(), README.read_text()
    bad = []
    for pattern, home in WITHDRAWN:
        for name, text in (("README.md", readme), ("analysis/accuracy/README.md", ACCURACY.read_text())):
            bad += [f"{name}: {m.group(0)!r}" for m in re.finditer(pattern, text)]
        for m in re.finditer(pattern, report):
            section = _section_of(report, m.start())
            if home is None or not section.startswith(home):
                bad.append(f"REPORT.md {section[:40]!r}: {m.group(0)!r}")
    assert not bad, bad


def _answers_paragraph(readme: str) -> str:
    analysis = readme[readme.index("## Analysis"):]
    analysis = analysis[:analysis.index("\n## ", 3)]
    paragraph = next(p for p in analysis.split("\n\n") if "The report answers" in p)
    return paragraph[paragraph.index("The report answers"):]


@pytest.mark.skipif(not REPORT.exists(), reason="no committed report here")
def test_the_readme_answers_are_the_reports():
    report = " ".join(REPORT.read_text().split())
    paragraph = " ".join(_answers_paragraph(README.read_text()).split())
    figs = [f for f, _ in figures(paragraph)]
    assert len(figs) >= 10  # the paragraph quotes the report's answers
    missing = [f for f in figs if f not in report]
    assert not missing, missing
    # "a ± b" and ranges as printed there
    for pair in re.findall(r"\d[\d.]*(?: ± |–)\d[\d.]*", paragraph):
        assert pair in report, pair
