"""The envelope's time constant read from a fitted model (vivbench.analysis.time_constant)."""

from __future__ import annotations

import numpy as np

from tests.helpers import assert_close
from vivbench.analysis import amplitude_slope, envelope_time_constant, short_events, valid_span
from vivbench.core.record import Record


class _Cubic:
    """dA/dt = c0 + c1 A + c2 A^2 + c3 A^3 (predict only)."""

    coef = np.array([1e-4, -0.01, 0.05, -2.0])

    def predict(self, record):
        return np.polynomial.polynomial.polyval(record.A, self.coef)


def _record(A, t=None):
    A = np.asarray(A, dtype=float).reshape(len(A), -1)
    t = np.arange(A.shape[0], dtype=float) if t is None else t
    return Record(event_id="E000", t=t, A=A, U=np.full(A.shape, 8.0))


def test_valid_span_is_the_longest_stretch_of_finite_amplitudes_without_a_gap():
    A = np.array([np.nan, 0.1, 0.2, 0.3, np.nan])
    assert valid_span(_record(A)) == 2.0
    assert valid_span(_record([np.nan, 0.1])) == 0.0
    assert valid_span(_record([np.nan, np.nan])) == 0.0
    # a NaN block or samples missing from the time axis split the event: its longest piece counts
    assert valid_span(_record([0.1, 0.1, 0.1, np.nan, 0.2, 0.2, 0.2, 0.2, 0.2])) == 4.0
    t = np.array([0.0, 1.0, 2.0, 3.0, 100.0, 101.0])
    assert valid_span(_record(np.full(6, 0.1), t)) == 3.0


def test_amplitude_slope_is_the_derivative_of_the_models_dA_dt_in_A():
    A = np.linspace(0.01, 0.1, 50)
    slope = amplitude_slope(_Cubic(), _record(A))
    c = _Cubic.coef
    assert_close(slope[:, 0], c[1] + 2 * c[2] * A + 3 * c[3] * A**2, rtol=1e-3,
                 reason="a forward difference with a relative step of 1e-3 of A")
    assert amplitude_slope(object(), _record(A)) is None


def test_the_time_constant_is_read_from_the_flagged_regime_1_windows_only():
    class Linear:
        def predict(self, record):
            return 0.002 - 0.004 * record.A  # relaxes with 1 / 0.004 = 250 s

    def verdict(record, start, end):
        shape = (start.size, record.n_sections)
        # regime 1 flagged in the first half, regime 3 (not counted) in the second
        regime = np.where(start[:, None] < 300.0, 1, 3) * np.ones(shape, dtype=int)
        return {"regime": regime, "identifiable": np.ones(shape, dtype=bool)}

    rec = _record(np.linspace(0.0, 0.5, 601), t=np.arange(601.0))
    assert_close(envelope_time_constant(Linear(), [rec], verdict), 250.0, rtol=1e-6,
                 reason="a forward difference of a linear prediction, exact up to rounding")
    none_flagged = lambda record, start, end: {"regime": np.ones((start.size, 1), dtype=int),  # noqa: E731
                                               "identifiable": np.zeros((start.size, 1), dtype=bool)}
    assert np.isnan(envelope_time_constant(Linear(), [rec], none_flagged))


def test_short_events_are_those_under_the_given_number_of_time_constants():
    assert short_events(["a", "b"], [900.0, 1100.0], 200.0, 5.0) == ["a"]
    assert short_events(["a", "b"], [900.0, 1100.0], float("nan"), 5.0) == ["a", "b"]
