"""Study l (converged): the model table, the certificate verdict, the side-by-side measures and its quick run.

The quick run (its part of the shared ``dicetrace analyze all --quick``, tests/studies/conftest.py: 21²
grids, CI-sized perturbations) checks the pipeline end to end and that
:func:`~dicetrace.studies.study_converged.rerender` reproduces the run's tables from its JSON and cached
grids (render changes no number). The full run is ``dicetrace analyze converged --out analysis``.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from dicetrace.studies import LETTERS, resolve
from dicetrace.studies import study_converged as conv
from dicetrace.studies.context import Options


def test_registered_as_study_l():
    assert LETTERS["l"] == "converged" and resolve(["l"]) == ["converged"]


def test_models_read_the_presets_and_take_the_overrides():
    from dicetrace.params import make_config

    m = conv.models()
    assert conv.model_config(m["discrete"]).numerics.integrator == "semi-implicit-euler"
    assert conv.model_config(m["converged"]).numerics.integrator == "contact-adaptive"
    assert conv.model_config(m["converged"]).numerics.tol == 1e-7
    # physical: whatever its preset's default integrator is
    assert conv.model_config(m["physical"]).numerics.integrator == make_config("physical").numerics.integrator
    o = conv.models(integrator="contact-substep", tol=1e-5)
    assert o["discrete"] == m["discrete"]  # the discrete model is never overridden
    assert o["converged"]["integrator"] == o["physical"]["integrator"] == "contact-substep"
    assert o["converged"]["tol"] == o["physical"]["tol"] == 1e-5


def test_integrator_overrides_are_not_the_committed_settings():
    assert Options().full
    assert not Options(integrator="contact-adaptive").full
    assert not Options(tol=1e-8).full


def _row(**kw):
    base = {"boundary_fraction": 0.9, "boundary_fraction_block_stderr": 0.01, "alpha": 0.1,
            "alpha_block_stderr": None, "alpha_stderr": 0.02, "alpha_pert": 0.5, "alpha_pert_stderr": 0.05,
            "dim_mask": 1.9, "dim_mask_stderr": 0.0, "Sb": 1.0, "Sb_stderr": 0.1, "Sbb": 1.0, "Sbb_stderr": 0.1,
            "settle": {"mean": 0.7, "mean_stderr": 0.01, "kappa": None, "kappa_stderr": None},
            "divergence": {"mean": 23.0, "mean_stderr": 1.0}}
    base.update(kw)
    return base


def test_changes_flag_differences_beyond_three_sigma_only():
    rows = {"discrete": _row(), "converged": _row(alpha_pert=0.8, Sb=1.2, alpha=0.2,
                                                  settle={"mean": 0.8, "mean_stderr": 0.01}),
            }
    rows["converged"]["chi2_p_vs_discrete"] = 1e-6
    ch = {c["key"]: c for c in conv.changes(rows)}
    assert ch["alpha_pert"]["changed"] and ch["alpha_pert"]["z"] == pytest.approx(0.3 / np.hypot(0.05, 0.05))
    assert not ch["Sb"]["changed"]  # 0.2 / 0.14 = 1.4 σ
    assert ch["alpha_box"]["changed"]  # the regression stderr stands in for a missing block stderr: 3.5 σ
    assert ch["settle_mean"]["changed"]
    assert "dim_mask" not in ch  # a zero error bar: not judged
    assert "kappa" not in ch  # no value: not judged
    assert ch["faces"]["changed"]


#: The grid of the quick run of study l.
QUICK_RES = 21


@pytest.fixture
def study_l(quick_run):
    """The output folder, options and results of study l in the shared quick run."""
    out, results = quick_run
    return out, Options(quick=True), results["converged"]


@pytest.mark.slow
def test_quick_run_measures_every_window_and_model(study_l):
    out, _, R = study_l
    assert R["res"] == QUICK_RES and R["windows"] == list(conv.WINDOWS)
    for w in conv.WINDOWS:
        for m in conv.MODEL_NAMES:
            r = R["by"][w][m]
            assert r["res"] == QUICK_RES and r["cells"]["n_nodes"] == QUICK_RES**2
            assert 0 <= r["certificate"]["fraction"] <= 1 and 0 <= r["floor"]["fraction"] <= 1
            assert r["certificate"]["ci"][0] <= r["certificate"]["fraction"] <= r["certificate"]["ci"][1]
            assert isinstance(r["converged"], bool)
            assert sum(f["count"] for f in r["fractions"].values()) + r["settle"]["n_unsettled"] <= QUICK_RES**2
            for key in ("boundary_fraction", "alpha", "Sb", "Sbb", "dim_mask"):
                assert key in r
            assert set(r["repetition"]) >= {"outcome_offcentre_max_corr", "texture_periods"}
        # the tighter run of an adaptive model lowers the tolerance; of the fixed-step one, the step
        assert R["by"][w]["converged"]["tight_tol"] == pytest.approx(R["by"][w]["converged"]["tol"] / 10)
        assert R["by"][w]["discrete"]["tight_dt_s"] == pytest.approx(R["by"][w]["discrete"]["dt_s"] / 10)
        assert "agreement_with_discrete" in R["by"][w]["converged"]
    for name in ("l_maps", "l_uncertainty", "l_alpha"):
        assert (out / R["figures"][name]["path"]).stat().st_size < 300_000
    for w in conv.WINDOWS:
        assert R["tables"][f"window_{w}"].count("\n") > 30
    assert "converged-seed maps certified" in R["tables"]["answer_alpha"]


@pytest.mark.slow
@pytest.mark.long
def test_rerender_reproduces_the_tables_without_simulating(study_l, tmp_path):
    run_out, opts, R = study_l
    out = tmp_path / "analysis"  # a copy: rerender rewrites the run's JSON and figures, which other tests read
    for part in ("results", "cache"):
        shutil.copytree(run_out / part, out / part)
    path = conv.rerender(out, opts)
    again = json.loads(path.read_text())
    assert again["tables"] == json.loads(json.dumps(R["tables"]))
    with pytest.raises(RuntimeError, match="not in"):
        conv.rerender(out, Options(quick=True, tol=1e-6))  # other grids: not cached


def test_alpha_pert_change_says_whether_it_passes_the_threshold():
    """The section-l sentence on α by perturbation follows the z of the home and zoom-out changes."""
    from dicetrace.studies.study_converged import _alpha_pert_change

    def by(zh, zz):
        return {w: {"changes": [{"key": "alpha_pert", "z": z}]} for w, z in (("home", zh), ("zoom-out", zz))}

    assert _alpha_pert_change(by(2.2, 1.3)) == "by 2.2 and 1.3 standard errors, not beyond the 3 σ threshold"
    assert _alpha_pert_change(by(3.8, 2.1)) == "by 3.8 and 2.1 standard errors, beyond the 3 σ threshold in home"
    assert _alpha_pert_change(by(None, 2.1)) == "(no error bar on one of them)"
