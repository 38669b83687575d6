"""The mean wind's yaw from the anemometers, and the varying-coefficient model with yaw as a second covariate."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from vivbench.core import Record
from vivbench.core.errors import InputError
from vivbench.models import VaryingCoefficientSINDy
from vivbench.preprocess import mean_yaw
from tests.helpers import assert_close, assert_not_close


@pytest.mark.parametrize("azimuth", [0.0, 30.0, 75.0])
@pytest.mark.parametrize("psi", [-20.0, 0.0, 12.0])
def test_mean_yaw_of_a_steady_wind(azimuth, psi):
    t = np.arange(0.0, 600.0, 1 / 32)
    a = np.radians(azimuth)
    normal = np.array([np.cos(a), -np.sin(a)])  # horizontal unit normal to the span (east, north)
    along = np.array([np.sin(a), np.cos(a)])
    p = np.radians(psi)
    vel = 8.0 * (np.cos(p) * normal + np.sin(p) * along)
    rng = np.random.default_rng(0)
    u = vel[0] + 0.5 * rng.standard_normal((t.size, 2))
    v = vel[1] + 0.5 * rng.standard_normal((t.size, 2))
    yaw = mean_yaw(t, u, v, azimuth)
    mid = slice(t.size // 4, 3 * t.size // 4)
    # 0.5 m/s white turbulence low-passed at 1/60 Hz leaves about 0.02 m/s: well under 1 degree at 8 m/s.
    assert_close(yaw[mid], psi, atol=0.5, reason="the low-passed turbulence moves the yaw by well under a degree")
    # the opposite wind direction has the same yaw's magnitude
    assert_close(np.abs(mean_yaw(t, -u, -v, azimuth)[mid]), abs(psi), atol=0.5, reason="as above: turbulence")


def bell(U):
    return -0.01 + 0.05 * np.exp(-0.5 * ((U - 10.0) / 1.5) ** 2)


def _records(n_events=10, seed=0, S=2, with_yaw=True):
    """dA/dt = bell(U) (1 - 4 sin^2 psi) A - 2 A^3, the yaw wandering within +-25 degrees."""
    rng = np.random.default_rng(seed)
    out = []
    for e in range(n_events):
        t = np.arange(0.0, 1200.0, 0.5)
        U = 7.0 + 6.0 * rng.random() + 2.0 * np.sin(2 * np.pi * t / (600 + 100 * e) + e)
        psi = 25.0 * (2 * rng.random() - 1) * np.cos(2 * np.pi * t / (900 + 70 * e))
        A = 0.05 + 0.1 * rng.random() * (1 + np.sin(2 * np.pi * t / 300 + e))
        U, psi = np.repeat(U[:, None], S, axis=1), np.repeat(psi[:, None], S, axis=1)
        A = A[:, None] * np.linspace(1.0, 0.6, S)[None, :]
        dA = bell(U) * (1 - 4 * np.sin(np.radians(psi)) ** 2) * A - 2.0 * A**3
        rec = Record(event_id=f"E{e:03d}", t=t, A=A, U=U, dA=dA)
        out.append(dataclasses.replace(rec, yaw=psi) if with_yaw else rec)
    return out


@pytest.fixture(scope="module")
def yaw_model():
    # Exact inputs (no errors-in-variables): the default 30 s wind smoothing would only blur them.
    return VaryingCoefficientSINDy(n_bootstrap=5, n_basis=(15,), yaw_degree=1, wind_smoothing_s=0.0).fit(_records())


def _err(model, rec):
    return float(np.sqrt(np.mean((model.predict(rec) - rec.dA) ** 2) / np.mean(rec.dA**2)))


def test_yaw_covariate_recovers_what_the_wind_alone_cannot(yaw_model):
    rec = _records(2, seed=7)[1]
    without = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(15,), yaw_degree=0, wind_smoothing_s=0.0).fit(_records())
    assert _err(yaw_model, rec) < 5e-3
    assert _err(without, rec) > 10 * _err(yaw_model, rec)
    # The curves of docs/concepts.md (coefficient curves) are those at yaw 0: the bell itself.
    wind = np.linspace(8.0, 12.0, 9)
    assert_close(yaw_model.curves(wind)["curves"].values[0, 1], bell(wind), atol=5e-4,
                 reason="a spline fit of the bell from noisy records, 1 % of its 0.05 1/s height")


def test_yaw_model_save_load_and_records_without_yaw(yaw_model, tmp_path):
    loaded = VaryingCoefficientSINDy.load(yaw_model.save(tmp_path / "m.nc"))
    rec = _records(1, seed=3)[0]
    np.testing.assert_array_equal(loaded.predict(rec), yaw_model.predict(rec))
    plain = Record(event_id="x", t=rec.t, A=rec.A, U=rec.U)
    assert np.isfinite(yaw_model.predict(plain)).all()  # the fitted median yaw stands in
    r = yaw_model.replicate_order_contributions(rec, 0, 2)
    assert r.shape == (2, rec.n_samples, 2, 4) and np.isfinite(r).all()
    with pytest.raises(InputError, match="yaw"):
        VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(11,), yaw_degree=1).fit(_records(3, with_yaw=False))
    with pytest.raises(InputError, match="yaw_degree"):
        VaryingCoefficientSINDy(yaw_degree=5).fit(_records(3))


def test_yaw_beyond_the_fitted_range_is_held_at_its_ends(yaw_model, tmp_path):
    """A yaw beyond every fitted one gives the curves at the fitted range's end (as a wind beyond it does), not a
    polynomial extrapolated in sin^2 psi; the range survives save and load."""
    zmax = yaw_model.yaw_max_
    assert zmax.shape == (2,) and np.all(zmax <= np.sin(np.radians(25.0)) ** 2 + 1e-12)
    assert np.all(yaw_model.yaw_min_ < zmax)
    rec = _records(1, seed=3)[0]
    edge = np.degrees(np.arcsin(np.sqrt(zmax)))[None, :]
    far = dataclasses.replace(rec, yaw=np.broadcast_to(edge + 40.0, rec.A.shape).copy())
    at_edge = dataclasses.replace(rec, yaw=np.broadcast_to(edge, rec.A.shape).copy())
    assert_close(yaw_model.predict(far), yaw_model.predict(at_edge), what="held at the fitted maximum")
    inside = dataclasses.replace(rec, yaw=np.broadcast_to(0.5 * edge, rec.A.shape).copy())
    assert_not_close(yaw_model.predict(inside), yaw_model.predict(at_edge), rtol=1e-3, what="inside: not held",
                     reason="half the edge's yaw changes the yaw term (-4 sin^2 psi) by far more than 0.1 %")
    wind = np.linspace(8.0, 12.0, 5)
    c_far = yaw_model.coefficient_values(np.repeat(wind[:, None], 2, axis=1), yaw=np.full((5, 2), 80.0))
    c_edge = yaw_model.coefficient_values(np.repeat(wind[:, None], 2, axis=1), yaw=np.repeat(edge, 5, axis=0))
    assert_close(c_far, c_edge, what="the curves are held too")
    loaded = VaryingCoefficientSINDy.load(yaw_model.save(tmp_path / "m.nc"))
    np.testing.assert_array_equal(loaded.yaw_max_, zmax)
    np.testing.assert_array_equal(loaded.predict(far), yaw_model.predict(far))


def test_held_yaw_per_equation_or_shared_and_unknown_ranges():
    from vivbench.models.varying_design import held_yaw

    z = np.array([[0.0, 0.5], [0.2, np.nan], [0.9, 0.1]])
    held = held_yaw(z, [0.1, 0.05], [0.3, 0.4], False)
    np.testing.assert_array_equal(held, [[0.1, 0.4], [0.2, np.nan], [0.3, 0.1]])
    # every equation takes every section's yaw: the range over every equation holds every column
    np.testing.assert_array_equal(held_yaw(z, [0.1, 0.05], [0.3, 0.4], True), [[0.05, 0.4], [0.2, np.nan], [0.4, 0.1]])
    # a file written before the range (NaN) or no range at all: nothing held
    np.testing.assert_array_equal(held_yaw(z, [np.nan, np.nan], [np.nan, np.nan], False), z)
    assert held_yaw(z, None, None, False) is z and held_yaw(None, [0.0], [1.0], False) is None


def test_yaw_and_smoothing_defaults_follow_the_records():
    """One default for every caller: yaw degree 1 when every record carries the yaw, else 0; 30 s smoothing."""
    with_yaw = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(_records(3))
    assert with_yaw.yaw_degree_ == 1 and with_yaw.wind_smoothing_s == 30.0
    plain = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,)).fit(_records(3, with_yaw=False))
    assert plain.yaw_degree_ == 0 and plain.coef_yaw_.shape[-1] == 0
    # The fit smooths the (measured) wind; measured_wind applies the same to a record for evaluation,
    # while predict takes a record's wind as given (a truth's own wind).
    from vivbench.preprocess import smooth_wind

    rec = _records(1, seed=5)[0]
    pre = VaryingCoefficientSINDy(n_bootstrap=0, n_basis=(8,), wind_smoothing_s=0.0)
    pre.fit([smooth_wind(r, 30.0) for r in _records(3)])
    assert_close(pre.coef_, with_yaw.coef_, atol=1e-12, reason="coefficients near zero: the same solve up to rounding")
    assert_close(with_yaw.predict(with_yaw.measured_wind(rec)), pre.predict(smooth_wind(rec, 30.0)), atol=1e-12,
                 reason="the same model, rounding near zero")
    assert_close(with_yaw.predict(rec), pre.predict(rec), atol=1e-12, reason="the same model, rounding near zero")


def test_identify_stores_the_yaw_and_records_carry_it(small_results, tmp_path):
    """The result's ``yaw`` is the anemometers' (as measured from the event file); records read it.

    A result written before the variable existed (``yaw`` dropped here) gets the same yaw from
    its event file through ``campaign``, and without it none.
    """
    import xarray as xr

    from vivbench.analysis import records_from_results, with_yaw
    from vivbench.io.result import read_result

    campaign, _dir, files = small_results
    ds = read_result(files[0])
    assert ds["yaw"].attrs["units"] == "degree" and ds["yaw"].shape == ds["U"].shape
    rec = records_from_results(files[:1])[0]
    np.testing.assert_array_equal(rec.yaw, ds["yaw"].values)
    plain = dataclasses.replace(rec, yaw=None)
    measured = with_yaw(plain, campaign.files[0])
    ok = np.isfinite(rec.U).all(axis=1)
    # identify's wind is despiked first; the small campaign has no spikes, so the two agree closely.
    assert_close(measured.yaw[ok], rec.yaw[ok], atol=1e-6, reason="the result stores the yaw in float32-rounded degrees")
    old = tmp_path / files[0].name
    xr.load_dataset(files[0]).drop_vars("yaw").to_netcdf(old)
    assert records_from_results([old])[0].yaw is None
    back = records_from_results([old], campaign=Path(campaign.files[0]).parent)[0]
    assert_close(back.yaw[ok], rec.yaw[ok], atol=1e-6, reason="as above")
