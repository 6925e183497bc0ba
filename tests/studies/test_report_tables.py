"""The report's table filter (``{{t:STUDY.NAME|drop=...}}``) and the words it uses for a certificate."""

from __future__ import annotations

from dicetrace.studies.report import drop_from_table, render
from dicetrace.studies.text import CONVERGED_MIN, verdict_word

TABLE = """| window | model | certificate | converged |
|---|---|---|---|
| home | physical | 0.985 | yes |
| converged | seed | 1.000 | yes |"""


def test_drop_removes_the_named_columns_and_rows():
    out = drop_from_table(TABLE, "drop=converged")
    assert out.splitlines() == ["| window | model | certificate |", "|---|---|---|", "| home | physical | 0.985 |"]
    assert drop_from_table(TABLE, "drop=model;home").splitlines()[2:] == ["| converged | 1.000 | yes |"]


def test_drop_without_a_match_or_spec_keeps_the_table():
    assert drop_from_table(TABLE, None) == TABLE
    assert drop_from_table(TABLE, ".3f") == TABLE
    assert drop_from_table("not a table", "drop=x") == "not a table"


def test_the_template_placeholder_drops():
    text, missing = render("{{t:s.tab|drop=certificate}}", {"s": {"tables": {"tab": TABLE}}})
    assert not missing and "certificate" not in text and "| home | physical | yes |" in text


def test_a_certificate_below_the_threshold_gives_statistics_only():
    assert CONVERGED_MIN == 0.99
    assert verdict_word(True, 1.0) == "converged"
    assert verdict_word(True, 0.861) == "statistics only"
    assert verdict_word(False, 1.0) == "not converged"
