"""pysindy variants (docs/methods.md, pysindy variants): ensembles, SBR and the weak form as campaign models,
their verdicts from draws, and their refusals."""

from __future__ import annotations

import sys

import numpy as np
import pysindy as ps
import pytest
from scipy.integrate import solve_ivp

from tests.helpers import assert_close
from vivbench.core import InputError, Record
from vivbench.models import PySINDyCampaign, PySINDyEnsemble, PySINDySBR, PySINDyWeak, sbr_available
from vivbench.validate import resolve_method, score_method

SPEC = "vivbench.models.pysindy_variants:"

# A known ODE with a time-varying input: dA/dt = (-0.02 + 0.004 (U - 8)) A - 3 A^3 (m/s), U(t) prescribed.
# Integrated to 1e-11, so A and dA are consistent (the weak form integrates A, it never sees dA).


def _ode_record(event_id: str, phase: float, *, duration: float = 400.0, dt: float = 0.25) -> Record:
    def wind(t):
        return 8.0 + 3.0 * np.sin(2 * np.pi * t / 90 + phase)

    def rhs(t, a):
        return (-0.02 + 0.004 * (wind(t) - 8.0)) * a - 3.0 * a**3

    t = np.arange(0.0, duration, dt)
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.06 + 0.02 * phase], t_eval=t, rtol=1e-11, atol=1e-13, method="DOP853")
    A = sol.y.T
    U = wind(t)[:, None]
    return Record(event_id=event_id, t=t, A=A, U=U, dA=rhs(t[:, None], A))


@pytest.fixture(scope="module")
def ode_records():
    return [_ode_record("E1", 0.0), _ode_record("E2", 1.0), _ode_record("E3", 2.0)]


@pytest.fixture(scope="module")
def small_measured(small_results):
    """The two identified events of the small realistic campaign: (records, truths)."""
    from vivbench.analysis import records_from_results
    from vivbench.io import read_event

    campaign, _out, results = small_results
    return records_from_results(results), [read_event(f)["truth"].ds for f in campaign.files[:2]]


def test_weak_form_recovers_a_known_model_with_a_time_varying_input(ode_records):
    exact = PySINDyCampaign(sindy=ps.SINDy(feature_library=ps.PolynomialLibrary(degree=3),
                                           optimizer=ps.STLSQ(threshold=1e-10))).fit(ode_records)
    weak = PySINDyWeak(threshold=1e-10).fit(ode_records)
    assert weak.feature_names_ == exact.feature_names_ and weak.n_test_functions_ > 100
    for rec in ode_records:
        scale = np.max(np.abs(rec.dA))
        # the weak system is integrated with pysindy's piecewise-linear rule on a 0.25 s grid: 1 % of dA/dt
        assert_close(weak.predict(rec), rec.dA, rtol=0.0, atol=0.01 * scale, reason="trapezoid-like weak integrals")
    assert_close(weak.order_contributions(ode_records[0]).sum(-1), weak.predict(ode_records[0]), rtol=1e-9,
                 reason="the four orders sum to predict (all terms are monomials)")


def test_ensemble_of_exact_data_agrees_everywhere_and_is_reproducible(ode_records):
    m = PySINDyEnsemble(threshold=1e-10, n_models=5, seed=3).fit(ode_records)
    again = PySINDyEnsemble(threshold=1e-10, n_models=5, seed=3).fit(ode_records)
    assert m.coef_draws_.shape == (5,) + m.coef_.shape
    np.testing.assert_array_equal(m.coef_draws_, again.coef_draws_)
    assert_close(m.coef_, m.coef_draws_.mean(axis=0), rtol=1e-12, reason="the mean of the bags, to rounding")
    rec = ode_records[0]
    start = np.arange(0.0, 350.0, 25.0)
    ok = m.identifiable(rec, start, start + 50.0)
    # every bag fits the same exact model: all draws agree on every window
    assert ok.shape == (start.size, 1) and ok.all()
    assert np.all(m.draw_agreement(rec, start, start + 50.0) == 1.0)


def test_ensemble_error_is_close_to_that_of_stlsq(small_measured):
    """On a realistic campaign the mean of the bags scores about as plain STLSQ (pysindy's median does not)."""
    records, truths = small_measured
    plain = score_method(PySINDyCampaign(), records, truths)
    mean = score_method(PySINDyEnsemble(n_models=10), records, truths)
    key = "rhs_error_true_AU_median"
    # The mean of linear fits predicts the mean of their predictions, each bag an STLSQ fit of a resample:
    # no worse than the full fit beyond resampling scatter (15 %: the campaign derivative's dA/dt, nearly
    # unsmoothed, scatters the bags more than the identification's smoothed one, 10 %), and better only by the
    # selection variance the averaging removes, not by the library's bias that both share (at most a factor 2).
    ratio = mean[key] / plain[key]
    assert 0.5 <= ratio <= 1.15, f"ensemble {mean[key]:.3g} against STLSQ {plain[key]:.3g}"
    assert 0.0 <= mean["coverage"] <= 1.0 and plain["coverage"] == 0.0


def test_ensemble_median_breaks_cancelling_coefficients(small_measured):
    """The bags' per-coefficient median is no bag's model: its error exceeds every bag's."""
    records, _truths = small_measured
    m = PySINDyEnsemble(n_models=10, aggregate="median").fit(records)
    rec = records[0]
    ok = np.all(np.isfinite(rec.dA), axis=1) & np.all(np.isfinite(m.predict(rec)), axis=1)
    bags = m.draw_contributions(rec).sum(-1)[ok]  # (n, D, S): every bag's dA/dt
    err = np.median(np.abs(bags - rec.dA[ok][:, None, :]), axis=(0, 2))
    err_median = np.median(np.abs(m.predict(rec)[ok] - rec.dA[ok]))
    err_mean = np.median(np.abs(bags.mean(axis=1) - rec.dA[ok]))
    assert err_median > err.max() and err_mean <= err.max(), (err_median, err_mean, err)


@pytest.mark.parametrize("name", ["ensemble", "weak"])
def test_accepted_variants_are_scored_through_their_specs(name, small_measured):
    records, truths = small_measured
    method = resolve_method(SPEC + name)
    if name == "ensemble":
        method.set_params(n_models=4)
    s = score_method(method, records, truths)
    assert s["n_scored"] > 0 and np.isfinite(s["rhs_error_true_AU_median"]) and 0.0 <= s["accuracy_all"] <= 1.0
    assert (s["coverage"] == 0.0) == (name == "weak"), "the ensemble has a verdict, the weak form none"


@pytest.mark.slow  # about 45 s of MCMC
@pytest.mark.skipif(not sbr_available(), reason="numpyro is not installed")
def test_sbr_gives_a_verdict_from_its_posterior_draws(small_measured, tmp_path):
    records, truths = small_measured
    assert isinstance(resolve_method(SPEC + "sbr"), PySINDySBR)
    m = PySINDySBR(degree=2, num_warmup=60, num_samples=60, n_draws=30, max_samples=300)
    s = score_method(m, records, truths)
    assert s["n_scored"] > 0 and np.isfinite(s["rhs_error_true_AU_median"]) and 0.0 <= s["coverage"] <= 1.0
    # its file keeps the posterior draws the verdict uses (vivbench.io.pysindy_model)
    back = PySINDySBR.load(m.save(tmp_path / "sbr.nc"))
    assert back.thinning_ == m.thinning_
    for rec in records:
        np.testing.assert_array_equal(back.draw_contributions(rec), m.draw_contributions(rec))
        np.testing.assert_array_equal(back.predict(rec), m.predict(rec))


def test_sbr_without_numpyro_is_refused_in_one_line(monkeypatch, ode_records):
    monkeypatch.setitem(sys.modules, "numpyro", None)  # find_spec gives None: as if not installed
    for call in (lambda: resolve_method(SPEC + "sbr"), lambda: PySINDySBR().fit(ode_records)):
        with pytest.raises(InputError, match="needs numpyro.*pip install numpyro") as info:
            call()
        assert "\n" not in str(info.value)


@pytest.mark.parametrize("adapter", [PySINDyCampaign, "windows"])
def test_weak_library_in_the_plain_adapters_is_refused_in_one_line(adapter, ode_records):
    from vivbench.models import PySINDyWindows

    t = ode_records[0].t
    sindy = ps.SINDy(feature_library=ps.WeakPDELibrary(function_library=ps.PolynomialLibrary(degree=3),
                                                       spatiotemporal_grid=t, K=20))
    model = PySINDyWindows(sindy=sindy) if adapter == "windows" else adapter(sindy=sindy)
    with pytest.raises(InputError, match="WeakPDELibrary.*PySINDyWeak") as info:
        model.fit(ode_records)
    assert "\n" not in str(info.value)
