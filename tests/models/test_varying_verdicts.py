"""The varying model's window verdicts from per-window Gram matrices equal the direct evaluation at every sample."""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import assert_close, bell_records
from vivbench.core import Record
from vivbench.core.regime import regime_rule
from vivbench.models import VaryingCoefficientSINDy
from vivbench.regimes import gram_order_stats, varying_window_verdicts, window_grams, window_order_stats


def _reference_verdicts(model, record, window_start, window_end):
    """The verdicts by evaluating every coefficient set's order contributions at every sample (the former code)."""
    t, A = record.t, record.A
    R, c1, nv = window_order_stats(model.order_contributions(record), A, t, window_start, window_end)
    point = np.where(nv > 0, regime_rule(np.nan_to_num(R), c1, model.tau), 0).astype(np.int8)
    r = model.replicate_order_contributions(record)
    Rb, c1b, _ = window_order_stats(r, A, t, window_start, window_end)
    agree = (regime_rule(np.nan_to_num(Rb), c1b, model.tau) == point[None]).mean(axis=0)
    Rs, c1s, _ = window_order_stats(model.subset_order_contributions(record), A, t, window_start, window_end)
    sub = regime_rule(np.nan_to_num(Rs), c1s, model.tau)
    set_agree = np.all((sub == point[None]) | ~model.subset_plausible_[:, None, :], axis=0)
    Rp, c1p, _ = window_order_stats(model.penalty_order_contributions(record), A, t, window_start, window_end)
    pen = regime_rule(np.nan_to_num(Rp), c1p, model.tau)
    set_agree &= np.all((pen == point[None]) | ~model.penalty_plausible_[:, None, :], axis=0)
    return {"regime": point, "identifiable": (agree >= model.agreement) & (point > 0) & set_agree,
            "agreement": agree, "order_rms": R, "model_set_agree": set_agree, "Rb": Rb, "c1b": c1b, "c1": c1}


def _records(n_events=6, seed=3, S=2):
    """Self-excited records with a yaw that modulates the linear term, 0.5 s samples, 15 min each."""
    return bell_records(n_events, seed=seed, duration_s=900.0, dt_s=0.5, mode_shape=np.linspace(1.0, 0.7, S),
                        wind_period_s=(500.0, 80.0), amplitude_period_s=250.0, yaw_deg=20.0, yaw_period_s=700.0,
                        yaw_in_truth=True, a0=0.002, a3=-2.0, noise_m_s=1e-4)


@pytest.fixture(scope="module", params=["section", "mean", "sum"])
def model(request):
    # "section": each section's own gaps reach its curves; "mean": the sections' mean wind and yaw fill them;
    # "sum": every section's wind and yaw enter every equation
    return VaryingCoefficientSINDy(n_basis=(8,), n_bootstrap=12, yaw_degree=1, wind_smoothing_s=0.0,
                                   block_s=150.0, wind_input=request.param).fit(_records())


def _awkward_record(rec):
    """Gaps in U, A and yaw, non-positive amplitudes: every validity mask of the window statistics is exercised."""
    U, A, yaw = rec.U.copy(), rec.A.copy(), rec.yaw.copy()
    U[100:140, 0] = np.nan
    A[300:320, 1] = np.nan
    yaw[500:530, 0] = np.nan
    A[700:760, 0] = 0.0
    A[760:770, 0] = -0.01
    U[1000:1200, :] = np.nan  # a window with no valid sample at all
    return Record(event_id=rec.event_id, t=rec.t, A=A, U=U, dA=rec.dA, yaw=yaw)


def test_fast_verdicts_equal_direct_evaluation(model):
    rec = _awkward_record(_records()[0])
    # overlapping windows, one empty, one running past the record's end, one starting before it
    ws = np.concatenate([np.arange(0.0, 860.0, 25.0), [-20.0, 880.0, 300.0]])
    we = np.concatenate([ws[:-3] + 50.0, [10.0, 950.0, 300.0]])
    fast = varying_window_verdicts(model, rec, ws, we)
    ref = _reference_verdicts(model, rec, ws, we)
    assert_close(fast["order_rms"], ref["order_rms"], rtol=1e-10, atol=1e-14, reason="rounding near zero")
    assert np.array_equal(np.isnan(fast["order_rms"]), np.isnan(ref["order_rms"]))
    for key in ("regime", "identifiable", "agreement", "model_set_agree"):
        np.testing.assert_array_equal(fast[key], ref[key], err_msg=key)
    assert (fast["regime"] == 0).any() and (fast["regime"] > 0).any()
    # the replicates' statistics themselves, not only their regimes
    stats = window_grams(model, rec, ws, we)
    Rb, c1b = gram_order_stats(stats, model.stacked_coefficients(model.coef_bootstrap_, model.coef_yaw_bootstrap_))
    assert_close(Rb, ref["Rb"], rtol=1e-10, atol=1e-14, reason="rounding near zero")
    assert_close(c1b, ref["c1b"], atol=1e-12, reason="rounding near zero")
    assert np.array_equal(np.isnan(c1b), np.isnan(ref["c1b"]))
    # and the order-subset models' (their regimes decide the model-set agreement)
    Rs, c1s = gram_order_stats(stats, model.stacked_coefficients(model.subset_coef_, model.subset_coef_yaw_))
    Rs_ref, c1s_ref, _ = window_order_stats(model.subset_order_contributions(rec), rec.A, rec.t, ws, we)
    assert_close(Rs, Rs_ref, rtol=1e-10, atol=1e-14, reason="rounding near zero")
    assert_close(c1s, c1s_ref, atol=1e-12, reason="rounding near zero")


def test_basis_rows_reproduce_the_curves(model):
    rec = _awkward_record(_records()[1])
    cols, vals = model.basis_rows(rec)
    theta = model.stacked_coefficients()
    a = np.stack([np.einsum("nq,nqi->ni", vals[:, k], theta[k][cols[:, k]]) for k in range(rec.n_sections)], axis=1)
    ref = model.coefficient_values(rec.U, yaw=rec.yaw)
    assert_close(a, ref, rtol=1e-12, atol=1e-15, reason="rounding near zero")


def test_non_finite_coefficients_fall_back_to_direct_evaluation(model):
    rec = _records()[2]
    ws = np.arange(0.0, 850.0, 50.0)
    bad = VaryingCoefficientSINDy(**model.get_params())
    bad.__dict__.update({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in model.__dict__.items()
                         if k.endswith("_")})
    # one replicate undefined: its curves are NaN everywhere (with several wind inputs, at the last one's spline)
    bad.coef_bootstrap_[0, 0, (bad.n_inputs(rec.n_sections) - 1) * bad.n_basis_[0], 1] = np.nan
    fast = varying_window_verdicts(bad, rec, ws, ws + 50.0)
    ref = _reference_verdicts(bad, rec, ws, ws + 50.0)
    for key in ("regime", "identifiable", "agreement"):
        np.testing.assert_array_equal(fast[key], ref[key], err_msg=key)
