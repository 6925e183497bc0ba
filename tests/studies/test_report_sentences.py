"""Sentences of the report that compare numbers are written from those numbers (``{{s:STUDY.NAME}}``).

The settle section compared the ``physical`` run's fitted rates with the discrete model's in fixed words
("a higher and broader rate ... few clean fits"); a quick run whose numbers said the opposite (``seed`` 31.3 ±
5.8 /s, ``physical`` 25.8 ± 0.4 /s, 3 clean fits each) printed the same words under its own table.
"""

from __future__ import annotations

import copy

import pytest

from dicetrace.studies.report import render, sections, template_text
from dicetrace.studies.study_settle import physical_vs_seed, rate_comparison


def _summary(median, se, q25, q75, n_clean, n_fits):
    return {"median": median, "median_stderr": se, "q25": q25, "q75": q75, "n_clean": n_clean, "n_fits": n_fits}


#: The committed full run's summaries (analysis/results/settle.json), rounded.
FULL_PHYSICAL = _summary(29.051, 0.571, 27.4744, 34.5222, 8, 60)
FULL_SEED = _summary(24.765, 0.931, 23.5324, 31.0849, 38, 80)
#: The quick run of the issue: physical lower, within the errors of seed's wide median.
QUICK_PHYSICAL = _summary(25.8, 0.4, 25.0, 27.0, 3, 6)
QUICK_SEED = _summary(31.3, 5.8, 24.0, 40.0, 3, 6)


def _say(other, base):
    return rate_comparison(other, base, "X", "Y")


def test_the_rate_is_higher_or_lower_as_the_medians_are():
    assert _say(FULL_PHYSICAL, FULL_SEED).startswith("X gives a higher rate than Y (median 29.1 ± 0.6 against "
                                                     "24.8 ± 0.9 /s)")
    assert _say(FULL_SEED, FULL_PHYSICAL).startswith("X gives a lower rate than Y (median 24.8 ± 0.9 against "
                                                     "29.1 ± 0.6 /s)")
    # 5.5 /s apart, two standard errors of the difference 11.7 /s: not told apart, in either order
    assert "a rate not told apart from that of Y" in _say(QUICK_PHYSICAL, QUICK_SEED)
    assert "a rate not told apart from that of Y" in _say(QUICK_SEED, QUICK_PHYSICAL)


def test_the_spread_and_the_clean_fits_are_compared_both_ways():
    narrow, broad = _summary(25, 0.1, 24, 26, 1, 10), _summary(25.5, 0.1, 20, 30, 5, 10)
    assert "a broader spread (interquartile range 10.0 against 2.0 /s) and more clean fits (5 of 10 sides against 1 " \
           "of 10)" in _say(broad, narrow)
    assert "a narrower spread (interquartile range 2.0 against 10.0 /s) and fewer clean fits (1 of 10 sides against " \
           "5 of 10)" in _say(narrow, broad)
    # the committed run: IQR 7.0 against 7.6 /s, within a tenth; 8 of 60 against 38 of 80
    full = _say(FULL_PHYSICAL, FULL_SEED)
    assert "a spread about as broad (interquartile range 7.0 against 7.6 /s) and fewer clean fits (8 of 60 sides " \
           "against 38 of 80)" in full
    assert "as many clean fits (3 of 6 sides against 3 of 6)" in _say(QUICK_PHYSICAL, QUICK_SEED)


def _settle_results(physical, seed):
    runs = {"seed": {"summary": seed}, "seed-substep": {"summary": seed}, "physical-substep": {"summary": physical}}
    return {"runs": copy.deepcopy(runs)}


@pytest.mark.parametrize("physical, seed, word, not_word", [
    (FULL_PHYSICAL, FULL_SEED, "a higher rate", "lower"),
    (QUICK_PHYSICAL, QUICK_SEED, "not told apart", "higher"),
    (_summary(20.0, 0.2, 19, 21, 1, 10), FULL_SEED, "a lower rate", "higher"),
])
def test_the_settle_section_says_what_its_numbers_say(physical, seed, word, not_word):
    template = "{{s:settle.physical_vs_seed}}; why was not analysed here."
    text, missing = render(template, {"settle": _settle_results(physical, seed)})
    assert not missing and word in text and not_word not in text.split(";")[0], text
    assert text == physical_vs_seed(_settle_results(physical, seed)) + "; why was not analysed here."


def test_the_settle_section_of_the_template_compares_through_the_sentence():
    section = sections(template_text())["settle"]
    assert "{{s:settle.physical_vs_seed}}" in section
    assert "higher and broader" not in section
