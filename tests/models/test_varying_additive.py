"""The varying-coefficient model with every section's wind summed (``wind_input="additive"``).

The truth of docs/concepts.md (the truth) sums the sections' aerodynamic forces, each at its own
felt wind, so with winds that differ along the span a curve of the mean wind
cannot represent it; the additive model can.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import assert_close, bell, bell_records
from vivbench.analysis.changes import statistics_change_scan, wind_strata
from vivbench.core import Record
from vivbench.models import VaryingCoefficientSINDy
from vivbench.regimes import model_window_regimes, varying_window_verdicts

#: Each section's share of the aerodynamic linear coefficient (they sum to one, so the curve at a uniform
#: wind U is bell(U)).
SHARE = np.array([0.5, 0.3, 0.2])
A3 = -2.0  # 1/(m^2 s)


def _records(n_events: int = 8, seed: int = 0):
    """Noise-free records of dA_k/dt = sum_j SHARE_j bell(U_j) A_k + A3 A_k^3, winds differing by +-1 m/s."""
    return bell_records(n_events, seed=seed, duration_s=1200.0, dt_s=2.0, mode_shape=np.linspace(1.0, 0.6, 3),
                        wind_period_s=(600.0, 100.0), amplitude_period_s=300.0, section_swing_m_s=1.0,
                        section_swing_period_s=(170.0, 37.0, 11.0), section_swing_phased=True, wind_shares=SHARE,
                        a3=A3)


def _fit(wind_input: str, n_bootstrap: int = 0):
    return VaryingCoefficientSINDy(n_bootstrap=n_bootstrap, wind_input=wind_input, n_basis=(11,),
                                   penalties=(1e-6,), wind_smoothing_s=0.0).fit(_records())


@pytest.fixture(scope="module")
def additive():
    return _fit("additive", n_bootstrap=5)


def _rel_err(model, rec):
    return float(np.sqrt(np.mean((model.predict(rec) - rec.dA) ** 2) / np.mean(rec.dA**2)))


def test_additive_recovers_sum_over_sections_that_mean_wind_cannot(additive):
    rec = _records(2, seed=9)[1]  # held out
    mean = _fit("mean")
    # The mean wind's curve is a smooth function of one variable: it cannot follow a sum of bells at three winds.
    assert _rel_err(mean, rec) > 0.03
    assert _rel_err(additive, rec) < 0.01
    assert additive.coef_.shape == (3, 3 * 11, 4)


def test_curves_at_uniform_wind_are_the_sum(additive):
    wind = np.linspace(8.0, 12.0, 9)
    c = additive.curves(wind)
    Uw = np.repeat(wind[:, None], 3, axis=1)
    assert_close(c["curves"].values, np.moveaxis(additive.coefficient_values(Uw), 0, -1), rtol=1e-7, reason="sums in another order")
    # The sum over the sections at a uniform wind is the truth's curve (each section's share separately is not
    # identifiable: constants can move between them).
    assert_close(c["curves"].values[:, 1], np.broadcast_to(bell(wind), (3, wind.size)), atol=2e-3, reason="a fit from noisy records")
    # Looser on A^3: with three winds each order's curve has three times the coefficients, and the smaller
    # amplitudes of equations 2-3 (0.8 and 0.6 of the first) excite the cubic order less.
    assert_close(c["curves"].values[:, 3], A3, rtol=0.06, reason="see above")
    # The sum written out: each section's block of B-splines evaluated at the same wind.
    M = int(additive.n_basis_[0])
    coef_one = additive.coef_[:, :M] + additive.coef_[:, M:2 * M] + additive.coef_[:, 2 * M:3 * M]
    from vivbench.models.varying import DEGREE, bspline_basis
    B = bspline_basis(wind, additive.knots_[0, :M + DEGREE + 1])
    assert_close(B @ coef_one[0], c["curves"].values[0].T, atol=1e-12, reason="rounding near zero")


def test_evaluation_paths_agree(additive):
    rec = _records(2, seed=4)[0]
    cols, vals = additive.basis_rows(rec)
    theta = additive.stacked_coefficients()
    a = np.einsum("nkq,nkqi->nki", vals, theta[np.arange(3)[None, :, None], cols])
    assert_close(a, additive.coefficient_values(rec.U), atol=1e-12, reason="rounding near zero")
    sim = additive.simulate(rec, t0=0.0, t1=200.0)
    assert np.isfinite(sim.A_sim).all() and sim.covered == 1.0
    v = varying_window_verdicts(additive, rec, np.array([0.0, 600.0]), np.array([60.0, 660.0]))
    reg = model_window_regimes(additive, rec, np.array([0.0, 600.0]), np.array([60.0, 660.0]))
    assert np.all(v["regime"] == reg["regime"])
    assert additive.equations()[0].startswith("dA1/dt = a10(U1..U3)")
    # A missing wind of another section leaves every equation undefined there (its term is missing).
    U = rec.U.copy()
    U[5:9, 2] = np.nan
    r = additive.order_contributions(Record(event_id="x", t=rec.t, A=rec.A, U=U))
    assert np.isnan(r[5:9]).all() and np.isfinite(r[10:]).all()


def test_save_load_round_trip(additive, tmp_path):
    loaded = VaryingCoefficientSINDy.load(additive.save(tmp_path / "add.nc"))
    rec = _records(1, seed=6)[0]
    np.testing.assert_array_equal(loaded.predict(rec), additive.predict(rec))
    np.testing.assert_array_equal(loaded.curves([9.0, 10.0])["curves_upper"].values,
                                  additive.curves([9.0, 10.0])["curves_upper"].values)
    assert loaded.get_params() == additive.get_params() and loaded.wind_input == "additive"


def test_event_statistics_feed_the_change_scan(additive):
    recs = _records()
    stats = additive.event_statistics(recs)
    p = 4 * 3 * 11
    assert stats[0]["G"].shape == (len(recs), p, p) and stats[0]["n_inputs"] == 3
    # The pooled statistics are those of the fitted design: their penalised solution fits the noise-free target.
    G, b, yy = stats[0]["G"].sum(axis=0), stats[0]["b"].sum(axis=0), stats[0]["yy"].sum()
    lam = stats[0]["penalty"] * np.trace(G) / np.trace(stats[0]["P"])
    c = np.linalg.solve(G + lam * stats[0]["P"], b)
    assert (c @ G @ c - 2 * c @ b + yy) / yy < 1e-3
    strata = wind_strata(stats, size=4)
    assert strata.shape == (len(recs),)
    scan = statistics_change_scan(stats, min_events=3, n_permutations=20, seed=0)
    assert not scan["detected"]  # no change in a noise-free, time-invariant campaign
