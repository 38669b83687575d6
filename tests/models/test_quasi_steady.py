"""The quasi-steady amplitude map (vivbench.models.QuasiSteadyAmplitude): the selection's null model."""

from __future__ import annotations

import numpy as np
import pytest

from tests.helpers import assert_close
from vivbench.core.errors import InputError
from vivbench.core.record import Record
from vivbench.models import QuasiSteadyAmplitude


def _slaved_records(n_events: int = 4, seed: int = 0) -> list[Record]:
    """Two sections whose amplitudes are a bell of the (slowly varying) wind: A = g(U), no dynamics."""
    rng = np.random.default_rng(seed)
    out = []
    for e in range(n_events):
        t = np.arange(0.0, 1200.0, 1.0)
        U = 9.0 + 3.0 * np.sin(2 * np.pi * t / rng.uniform(600.0, 1500.0) + rng.uniform(0, 2 * np.pi))
        g = 0.02 * np.exp(-((U - 9.5) / 1.5) ** 2)
        A = np.stack([g, 0.6 * g], axis=1)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A, U=np.stack([U, U], axis=1),
                          dA=np.gradient(A, t, axis=0)))
    return out


def test_the_map_recovers_an_amplitude_slaved_to_the_wind():
    recs = _slaved_records()
    m = QuasiSteadyAmplitude(wind_smoothing_s=0.0).fit(recs[:3])
    held = recs[3]
    # 12 cubic B-splines over 6 m/s against a Gaussian bell of width 1.5 m/s: a few per cent of its peak
    assert_close(m.amplitude(held), held.A, atol=1e-3 * 0.02 * 20, reason="spline approximation of a bell")
    sim = m.simulate(held, 100.0, 900.0)
    assert sim.t[0] == 100.0 and sim.t[-1] == 900.0
    assert_close(sim.A_sim, m.amplitude(held)[100:901], rtol=0.0, reason="the simulation is the map itself")
    assert_close(m.predict(held), np.gradient(m.amplitude(held), held.t, axis=0), rtol=0.0,
                 reason="the same finite difference")


def test_the_smoothing_is_that_of_the_measured_wind():
    recs = _slaved_records(2)
    m = QuasiSteadyAmplitude(wind_smoothing_s=20.0)
    smoothed = m.measured_wind(recs[0])
    assert not np.array_equal(smoothed.U, recs[0].U)
    assert np.array_equal(smoothed.A, recs[0].A)


@pytest.mark.parametrize("params, match", [({"n_basis": 3}, "n_basis"), ({"wind_smoothing_s": -1.0}, "seconds"),
                                           ({"penalties": ()}, "penalties")])
def test_bad_settings_are_refused(params, match):
    with pytest.raises(InputError, match=match):
        QuasiSteadyAmplitude(**params).fit(_slaved_records(2))


def test_an_unfitted_map_and_a_wrong_record_are_refused():
    recs = _slaved_records(2)
    with pytest.raises(InputError, match="not fitted"):
        QuasiSteadyAmplitude().amplitude(recs[0])
    m = QuasiSteadyAmplitude().fit(recs)
    one = Record(event_id="x", t=recs[0].t, A=recs[0].A[:, :1], U=recs[0].U[:, :1])
    with pytest.raises(InputError, match="sections"):
        m.amplitude(one)
    with pytest.raises(InputError, match="no parameter"):
        m.set_params(degree=2)
