"""The varying model's confidence set of penalties: the verdict needs every plausible penalty's fit to agree."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tests.helpers import assert_close, bell_records, close_mask
from vivbench.models import VaryingCoefficientSINDy
from vivbench.regimes import varying_window_verdicts


def _records(n_events: int = 8, seed: int = 1, S: int = 2):
    """Noisy records dA/dt = a_1(U) A - 2 A^3 + noise, a lock-in bell a_1 over 5-15 m/s, 0.5 s samples."""
    return bell_records(n_events, seed=seed, duration_s=900.0, dt_s=0.5, mode_shape=np.linspace(1.0, 0.7, S),
                        wind_period_s=(500.0, 80.0), amplitude_period_s=250.0, a3=-2.0, noise_m_s=2e-4)


SETTINGS = dict(n_basis=(8,), wind_smoothing_s=0.0, eiv_weights=False, block_s=150.0)


@pytest.fixture(scope="module")
def fitted():
    return VaryingCoefficientSINDy(n_bootstrap=10, **SETTINGS).fit(_records())


def test_penalty_set(fitted):
    pen = np.asarray(fitted.penalties)
    assert fitted.penalty_coef_.shape == (pen.size,) + fitted.coef_.shape
    chosen = np.flatnonzero(close_mask(pen, fitted.penalty_[0], rtol=1e-5, reason="a penalty of the grid"))[0]
    assert_close(fitted.penalty_coef_[chosen], fitted.coef_, atol=1e-12, reason="rounding near zero")
    # eight events see the bell: the near-linear curves of the largest penalties predict them worse
    assert fitted.penalty_plausible_.any(axis=0).all() and not fitted.penalty_plausible_.all()
    assert not fitted.penalty_plausible_[-1].any()
    # two events: a paired test over two events rejects nothing, every penalty stays plausible
    two = VaryingCoefficientSINDy(n_bootstrap=0, **SETTINGS).fit(_records(2))
    assert two.penalty_plausible_.all()


def _copy(model):
    out = VaryingCoefficientSINDy(**model.get_params())
    out.__dict__.update({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in model.__dict__.items()
                         if k.endswith("_")})
    return out


def test_verdict_needs_every_plausible_penalty(fitted):
    rec = _records(1, seed=9)[0]
    ws = np.arange(0.0, 850.0, 50.0)
    base = _copy(fitted)
    base.penalty_coef_ = base.penalty_coef_yaw_ = base.penalty_plausible_ = None  # bootstrap and order subsets
    v0 = varying_window_verdicts(base, rec, ws, ws + 50.0)
    assert v0["identifiable"].any()
    # a plausible penalty whose fit has no A^2, A^3 terms and the opposite net damping: no window whose regime
    # that changes stays identifiable
    flipped = _copy(fitted)
    flipped.penalty_coef_[:] = flipped.coef_
    flipped.penalty_coef_[0, :, :, 1] *= -1.0
    flipped.penalty_coef_[0, :, :, 2:] = 0.0
    flipped.penalty_plausible_[:] = True
    v = varying_window_verdicts(flipped, rec, ws, ws + 50.0)
    assert v["identifiable"].sum() < v0["identifiable"].sum() and not (v["identifiable"] & ~v0["identifiable"]).any()
    # the same fit outside the set changes nothing
    flipped.penalty_plausible_[0] = False
    np.testing.assert_array_equal(varying_window_verdicts(flipped, rec, ws, ws + 50.0)["identifiable"],
                                  v0["identifiable"])


def test_save_load_and_older_files(fitted, tmp_path):
    path = fitted.save(tmp_path / "m.nc")
    loaded = VaryingCoefficientSINDy.load(path)
    np.testing.assert_array_equal(loaded.penalty_coef_, fitted.penalty_coef_)
    np.testing.assert_array_equal(loaded.penalty_plausible_, fitted.penalty_plausible_)
    rec = _records(1, seed=9)[0]
    ws = np.arange(0.0, 850.0, 50.0)
    ref = varying_window_verdicts(fitted, rec, ws, ws + 50.0)
    for key, val in varying_window_verdicts(loaded, rec, ws, ws + 50.0).items():
        np.testing.assert_array_equal(val, ref[key], err_msg=key)
    with xr.open_dataset(path) as ds:
        old = ds.load().drop_vars(["penalty_coef", "penalty_plausible"])
    old.to_netcdf(tmp_path / "old.nc")
    older = VaryingCoefficientSINDy.load(tmp_path / "old.nc")
    assert older.penalty_coef_ is None and older.penalty_order_contributions(rec) is None
    assert varying_window_verdicts(older, rec, ws, ws + 50.0)["identifiable"].shape == (ws.size, 2)
