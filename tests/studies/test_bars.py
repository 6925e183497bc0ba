"""Study bars: long bars against Pender & Uhrin's formula, its committed results, its quick run and its report section."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from dicetrace.analysis.fairness import pender_uhrin_p, pender_uhrin_ratio
from dicetrace.params import make_config
from dicetrace.studies import report
from dicetrace.studies import study_bars as sb

REPO = Path(__file__).resolve().parents[2]
COMMITTED = REPO / "analysis" / "bars"


@pytest.fixture(scope="module")
def committed():
    path = COMMITTED / "results.json"
    if not path.exists():
        pytest.skip("the committed bar results are not in this checkout")
    return json.loads(path.read_text())


def test_the_wide_faces_are_those_the_bar_rests_lowest_on():
    """The faces counted as wide (2, 5) are those on which the bar's centre rests at k/2, the narrow ones (3, 4) at
    l/2, the ends (1, 6) at half its length: the body's own geometry, not the study's labels."""
    for ratio in (1.25, 2.5):
        heights = make_config("physical", half_extents_cm=sb.half_extents(ratio)).preset.body.face_heights_cm
        for faces, h in ((sb.WIDE, 0.5 * sb.K_CM), (sb.NARROW, 0.5 * sb.K_CM * ratio), (sb.END, sb.HALF_LENGTH_CM)):
            for f in faces:  # a face up rests on its opposite, 7 - f, of the same pair
                assert heights[7 - f - 1] == pytest.approx(h)
    assert sb.HALF_LENGTH_CM >= 5 * 0.5 * sb.K_CM * max(sb.RATIOS)


def test_counts_sort_every_throw_and_map_the_wilson_interval_onto_the_ratio():
    outcome = np.array([2, 5, 5, 3, 4, 1, 6, 0, -1, -2] + [2] * 40 + [3] * 10)
    c = sb.counts(outcome)
    assert (c["wide"], c["narrow"], c["end"], c["edge"], c["unsettled"]) == (43, 12, 2, 1, 2)
    assert sum(c["by_face"]) + c["edge"] + c["unsettled"] == outcome.size
    ci = stats.binomtest(43, 55).proportion_ci(method="wilson")
    assert (c["ci_low"], c["ci_high"]) == pytest.approx((ci.low, ci.high), rel=1e-10)
    assert c["R"] == pytest.approx(43 / 12)
    assert (c["R_low"], c["R_high"]) == pytest.approx((ci.low / (1 - ci.low), ci.high / (1 - ci.high)), rel=1e-10)
    empty = sb.counts(np.array([1, 6, 0]))
    assert empty["n"] == 0 and np.isnan(empty["R"])


def test_summarise_on_exact_shares_passes_and_on_far_shares_refutes():
    """Rows whose counts are the formula's own shares pass at every throw model (χ² ≈ 0, supported); shares half
    way to 1/2 fail even with a small throw spread (refuted)."""
    def rows(scale):
        out = []
        for r in sb.RATIOS:
            for variant, n in (("casual", sb.N_MAIN), ("gentle", sb.N_SYST), ("vigorous", sb.N_SYST),
                               ("casual, twice as long", sb.N_MAIN)):
                if "long" in variant and r != sb.LONG_RATIO:
                    continue
                p0 = pender_uhrin_p(sb.K_CM, sb.K_CM * r)
                p = 0.5 + scale * (p0 - 0.5)
                wide = int(round(p * n))
                by_face = [0, wide // 2, (n - wide) // 2, n - wide - (n - wide) // 2, wide - wide // 2, 0]
                out.append({"ratio": r, "variant": variant, "throw": variant.split(",")[0], "throws": n,
                            **sb.counts(np.repeat(np.arange(1, 7), by_face)),
                            "R_pu": float(pender_uhrin_ratio(sb.K_CM, sb.K_CM * r)), "p_pu": p0})
        return {"rows": out, "ratios": list(sb.RATIOS), "long_ratio": sb.LONG_RATIO}

    good = sb.summarise(rows(1.0))
    assert good["verdict"] == "supported" and good["models"]["casual"]["chi2"] < 1
    assert good["square"]["one_inside"] and good["opposite_faces"]["p_value"] > 0.5
    bad = sb.summarise(rows(0.5))
    assert bad["verdict"] == "refuted" and bad["direction"].startswith("below the formula's at each of the")


def test_the_committed_run_is_the_full_study(committed):
    rows = pd.DataFrame(committed["rows"])
    assert committed["ratios"] == list(sb.RATIOS) and committed["long_ratio"] == sb.LONG_RATIO
    assert (rows.loc[rows["variant"] == "casual", "throws"] == sb.N_MAIN).all()
    assert (rows.loc[rows["variant"].isin(["gentle", "vigorous"]), "throws"] == sb.N_SYST).all()
    assert len(rows) == 3 * len(sb.RATIOS) + 1
    # every throw counted: a wide or narrow side, an end, an edge or the time cap
    assert (rows["wide"] + rows["narrow"] + rows["end"] + rows["edge"] + rows["unsettled"] == rows["throws"]).all()
    for _, r in rows.iterrows():
        assert r["p_pu"] == pytest.approx(pender_uhrin_p(sb.K_CM, sb.K_CM * r["ratio"]), rel=1e-12)
        assert r["half_extents_cm"][1:] == pytest.approx([0.5 * sb.K_CM, 0.5 * sb.K_CM * r["ratio"]])


def test_the_square_bar_and_opposite_faces_show_the_symmetry(committed):
    """A square section has no wide side: R = 1 inside its 95 % interval; opposite faces alike over every run."""
    s = committed["summary"]
    assert s["square"]["one_inside"] and s["square"]["R_low"] <= 1 <= s["square"]["R_high"]
    assert s["opposite_faces"]["p_value"] > 0.001


def test_the_committed_summary_follows_from_its_rows(committed):
    again = sb.summarise({k: committed[k] for k in ("rows", "ratios", "long_ratio")})
    s = committed["summary"]
    assert again["verdict"] == s["verdict"] and again["direction"] == s["direction"]
    for name, m in s["models"].items():
        assert again["models"][name]["chi2"] == pytest.approx(m["chi2"], rel=1e-12)
    assert again["casual_with_systematic"]["chi2"] == pytest.approx(s["casual_with_systematic"]["chi2"], rel=1e-12)
    assert again["length"] == pytest.approx(s["length"], rel=1e-12)
    text = (COMMITTED / "bars.md").read_text()
    assert f"long bars: **{s['verdict']}**" in text
    for name, m in s["models"].items():
        assert f"| {name} | {m['chi2']:.1f} | {m['dof']} |" in text


def _report_fields_resolve(res: dict, study: str, title: str) -> None:
    """Every placeholder of the report's section of ``study`` finds its value in ``res``."""
    text, missing = report.render(report.titled_section(title), {study: res})
    assert not missing, missing
    assert "{{" not in text and "n/a" not in text


def test_the_committed_results_fill_the_report_section(committed):
    _report_fields_resolve(committed, "bars", "Real dice II")
    assert re.search(r"long bars: \*\*(supported|refuted|undetermined)\*\*", (REPO / "analysis" / "REPORT.md").read_text())


@pytest.mark.slow
@pytest.mark.long
def test_the_quick_run_writes_every_file_the_report_reads(tmp_path, dicetrace_cli):
    res = dicetrace_cli("analyze", "bars", "--quick", "--quiet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    out = tmp_path / "dicetrace-results" / "bars"  # the default folder
    for name in ("bars.csv", "results.json", "bars.md", "bars.png"):
        assert (out / name).stat().st_size > 0
    data = json.loads((out / "results.json").read_text())
    assert data["summary"]["verdict"].startswith("none")
    rows = pd.DataFrame(data["rows"])
    assert set(rows["ratio"]) == set(sb.QUICK["ratios"])
    assert (rows["wide"] + rows["narrow"] + rows["end"] + rows["edge"] + rows["unsettled"] == rows["throws"]).all()
    _report_fields_resolve(data, "bars", "Real dice II")
    sb.rerender(out)  # again from the results alone: the same summary
    assert json.loads((out / "results.json").read_text())["summary"] == data["summary"]


def test_bad_input_is_one_line(tmp_path, dicetrace_cli):
    res = dicetrace_cli("analyze", "bars", "--threads", "0", "--out", str(tmp_path / "x"), cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.strip().count("\n") == 0 and "--threads" in res.stderr
    assert not (tmp_path / "x").exists()
    res = dicetrace_cli("analyze", "bars", "--res", "5", cwd=tmp_path)
    assert res.returncode == 2 and "--res" in res.stderr
    res = dicetrace_cli("analyze", "bars", "--quick", "--out", str(REPO / "analysis" / "bars"), cwd=tmp_path)
    assert res.returncode == 2 and "--quick" in res.stderr and res.stderr.strip().count("\n") == 0
