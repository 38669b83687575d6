"""The varying model's confidence set of order subsets, its verdict on a forced-only bridge, and the wind smoothing."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from vivbench.preprocess import smooth_wind
from vivbench.core import Record
from vivbench.models import VaryingCoefficientSINDy
from vivbench.models.varying import ORDER_SUBSETS
from vivbench.regimes import varying_window_verdicts
from tests.helpers import REPO, assert_close


def r0(U):
    """Locked shedding force (forcing only), m/s."""
    return 0.004 * np.exp(-0.5 * ((U - 8.0) / 1.5) ** 2) + 0.0002


def a1(U):
    """Net linear coefficient, negative everywhere (no self-excitation), 1/s."""
    return -0.008 + 0.004 * np.exp(-0.5 * ((U - 8.0) / 1.5) ** 2)


def _forced_records(n=10, seed=0, eiv=0.4):
    """A forced-only bridge (truth regime 1 everywhere) seen through a mean wind with slow errors (0.4 m/s rms)."""
    rng = np.random.default_rng(seed)
    dt, out = 0.5, []
    for e in range(n):
        t = np.arange(0.0, 1800.0, dt)
        U = 5.0 + 6.0 * rng.random() + 2.5 * np.sin(2 * np.pi * t / (1200 + 150 * e) + e)
        A = np.empty_like(t)
        A[0] = -r0(U[0]) / a1(U[0])
        for i in range(t.size - 1):  # explicit Euler: the test's own truth, a few thousand steps
            A[i + 1] = A[i] + dt * (r0(U[i]) + a1(U[i]) * A[i])
        noise = gaussian_filter1d(rng.standard_normal(t.size), 40.0 / dt)
        Um = U + eiv * noise / noise.std()
        dA = r0(U) + a1(U) * A + 1e-5 * rng.standard_normal(t.size)
        out.append(Record(event_id=f"E{e:03d}", t=t, A=A[:, None], U=Um[:, None], dA=dA[:, None]))
    return out


def test_forced_only_bridge_gets_no_self_excited_flag():
    recs = _forced_records()
    model = VaryingCoefficientSINDy(n_bootstrap=30, n_basis=(11,)).fit(recs)
    # the model without A^2 and A^3 predicts the held-out events about as well: it is in the confidence set
    linear_only = np.flatnonzero((ORDER_SUBSETS == [True, True, False, False]).all(axis=1))[0]
    assert model.subset_plausible_[linear_only, 0]
    ws = np.arange(0.0, 1750.0, 50.0)
    boot_only_self = flagged_self = 0
    for rec in recs:
        v = varying_window_verdicts(model, rec, ws, ws + 50.0)
        reg = v["regime"][:, 0]
        boot_only_self += int(((v["agreement"][:, 0] >= model.agreement) & (reg >= 2)).sum())
        flagged_self += int((v["identifiable"][:, 0] & (reg >= 2)).sum())
        assert np.all(v["identifiable"] <= v["model_set_agree"])
    # The misfit bends the forced plateaus with A^2, A^3: the bootstrap alone agrees on regimes 3 and 4 ...
    assert boot_only_self > 50
    # ... the confidence set of models does not.
    assert flagged_self == 0


def test_confidence_set_keeps_models_within_noise_of_the_best():
    from vivbench.regression import confidence_set

    rng = np.random.default_rng(1)
    base = 1.0 + rng.random(30)
    loss = np.stack([base, base + 0.01 * rng.standard_normal(30), base + 0.3, base * 1.5])
    keep = confidence_set(loss, 0.95)
    assert keep.tolist() == [True, True, False, False]


def test_smooth_wind_keeps_level_gaps_and_yaw():
    t = np.arange(0.0, 600.0, 0.5)
    rng = np.random.default_rng(2)
    U = 8.0 + 0.3 * rng.standard_normal((t.size, 2))
    U[100:120, 1] = np.nan
    rec = Record(event_id="e", t=t, A=np.ones_like(U), U=U, yaw=np.full(U.shape, 10.0))
    out = smooth_wind(rec, 30.0)
    assert out.yaw is not None and np.isnan(out.U[100:120, 1]).all()
    # white noise through a 30 s Gaussian at 2 Hz: rms factor (2 sqrt(pi) 60)^-1/2 = 0.069 (plus the gap)
    assert np.isfinite(out.U[:100]).all() and np.nanstd(out.U) < 0.15 * np.nanstd(U)
    assert_close(np.nanmean(out.U), 8.0, atol=0.02, reason="the smoothed noise leaves about 0.07 of its rms in the mean")
    assert_close(out.yaw, 10.0)
    assert smooth_wind(rec, 0.0) is rec


@pytest.mark.slow
def test_forced_only_campaign_through_the_chain_gets_no_self_excited_flag(tmp_path):
    """examples/forced_only.toml, 8 events of 20-30 min: synth, identify, pool --model varying --campaign."""
    import xarray as xr

    from vivbench.cli import main

    camp, ident = tmp_path / "camp", tmp_path / "id"
    assert main(["synth", "--events", "8", "--duration", "20-30", "--seed", "3", "--config",
                 str(REPO / "examples" / "forced_only.toml"), "--out", str(camp)]) == 0
    assert main(["identify", str(camp), "--out", str(ident)]) == 0
    assert main(["pool", str(ident), "--model", "varying", "--campaign", str(camp)]) == 0
    with xr.open_dataset(ident / "campaign.regimes.nc") as ds:
        flagged = ds["identifiable"].values.astype(bool)
        regime = ds["regime"].values
    assert (regime >= 2).sum() > 0  # the point regimes are wrong somewhere: the verdict has something to refuse
    assert not (flagged & (regime >= 2)).any()
